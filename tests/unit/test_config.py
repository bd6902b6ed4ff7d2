"""Every calibration option is validated once, in CalibrationConfig, with the one-line contract."""

import pytest

from robocal.calibration.config import CalibrationConfig
from robocal.exceptions import InputError

BAD = [
    ({"method": "sgd"}, "method", "unknown method"),
    ({"frames": "tool"}, "frames", "unknown frames mode"),
    ({"loss": "hubber"}, "loss", "unknown loss 'hubber'"),
    ({"loss": "huber", "method": "pso"}, "loss", "applies to lm and hybrid"),
    ({"f_scale": 0}, "f_scale", "> 0"),
    ({"f_scale": float("nan")}, "f_scale", "finite"),
    ({"particles": 0}, "particles", "≥ 1"),
    ({"iterations": -3}, "iterations", "≥ 1"),
    ({"box": "0,1"}, "box", "half-widths must be > 0"),
    ({"box": "0.5"}, "box", "finite comma-separated numbers"),
    ({"objective": "max"}, "objective", "unknown objective"),
    ({"halton": "sobol"}, "halton", "unknown Halton start"),
    ({"k": -1}, "k", "> 0"),
    ({"noise": 0}, "noise", "> 0"),
    ({"angle_noise": -0.1}, "angle_noise", "> 0"),
    ({"angle_noise": 1e-5, "k": 1e4}, "k", "not both"),
    ({"seed": -1}, "seed", "≥ 0"),
    ({"seed": "abc"}, "seed", "integer"),
    ({"params": ""}, "params", "no parameter names"),
    ({"swarm": {"omega": 0.5}, "method": "pso"}, "swarm", "unknown setting 'omega'"),
    ({"backend": "gpu"}, "backend", "unknown backend"),
    ({"max_evaluations": 0}, "max_evaluations", "≥ 1"),
]


@pytest.mark.parametrize("options,option,message", BAD)
def test_bad_values_name_their_option(options, option, message):
    with pytest.raises(InputError) as info:
        CalibrationConfig(**options)
    assert info.value.option == option and message in str(info.value)
    assert info.value.render(cli=True).startswith(f"--{option.replace('_', '-')}: ")
    assert str(info.value).startswith(f"option '{option}': ")


def test_defaults_and_coercions():
    c = CalibrationConfig(method="pso", box="0.5,0.01", params="a1, d2,a1", seed="4")
    assert c.objective_kind == "sum_norms" and c.box == (0.5, 0.01) and c.params == ("a1", "d2") and c.seed == 4
    assert CalibrationConfig(params="wen2019").params == "wen2019" and CalibrationConfig(params="auto").params is None
    # all: every joint parameter, whatever the data (auto chooses among the sets for camera rows)
    assert CalibrationConfig(params="all").params == "all" and CalibrationConfig(params="zeros").params == "zeros"
    assert CalibrationConfig.build(c, method="lm").method == "lm"
    with pytest.raises(TypeError):
        CalibrationConfig.build(None, speed=3)


def test_the_calibrate_command_and_the_config_cannot_drift_apart():
    """Every option of ``robocal calibrate`` sets the config field of its name or is one of the
    command's own; every config field a user sets has its option (or is set another way)."""
    import inspect
    from dataclasses import fields

    from robocal.calibration.config import CalibrationConfig
    from robocal.cli.calibrate import CLI_ONLY, CONFIG_FIELDS, calibrate_cmd

    options = set(inspect.signature(calibrate_cmd).parameters)
    config = {f.name for f in fields(CalibrationConfig)}
    assert set(CONFIG_FIELDS) <= config
    assert options == set(CONFIG_FIELDS) | set(CLI_ONLY)
    # set otherwise: --position-only → use_orientation; per-setting swarm overrides and LM's cap
    # are for the Python API and studies
    assert config - set(CONFIG_FIELDS) == {"use_orientation", "swarm", "max_evaluations"}
