"""The workloads of robocal's speed targets.

Every figure is a median of repeated runs on this machine; ratios come from runs
interleaved in the same process.  Compiled kernels are warmed up before timing, so the
figures are of the work, not of numba's one-off compilation.
"""

from __future__ import annotations

import json
import os
import statistics
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..backend import numba_installed
from ..calibration import calibrate
from ..calibration.fit.problem import Setup
from ..io.robotfile import load_robot
from ..model.kinematics import chain_points
from ..model.parameters import ParameterSpace, is_angle
from ..optimize.swarm import ipso, ldpso_bt, pso
from ..presets import kou2022, wen2019
from ..simulation import simulate
from .timing import Row, median_time, run_measured


def wen2019_problem(backend: str = "auto"):
    """Wen 2019: ER10L-C10, 32 full poses, the paper's 24 parameters, and IPSO's search box."""
    robot = load_robot("er10l-c10")
    sim = simulate(robot, wen2019.POSES, deviations="paper", seed=1)
    setup = Setup(ParameterSpace.of(robot), sim.measurements, backend=backend)
    prob = setup.problem(wen2019.PARAMETERS)
    box = np.array([wen2019.BOX[1] if is_angle(n) else wen2019.BOX[0] for n in prob.names])
    return prob, box


def kou2022_problem():
    """Kou 2022: KR5 arc, 30 position-only poses, Δa, Δd, Δα, Δθ of all joints, and the swarm box."""
    robot = load_robot("kr5-arc")
    sim = simulate(robot, kou2022.POSES, deviations=kou2022.DEVIATIONS, seed=1, measure="position")
    setup = Setup(ParameterSpace.of(robot), sim.measurements)
    prob = setup.problem(kou2022.parameters())
    box = np.array([kou2022.BOX[1] if is_angle(n) else kou2022.BOX[0] for n in prob.names])
    return prob, box, sim


def _compiled() -> str:
    """``numba`` where it is installed (compiled here if this process has not), else numpy."""
    return "numba" if numba_installed() and not os.environ.get("ROBOCAL_NO_NUMBA") else "numpy"


def w1_ipso(repeats: int = 5) -> list[Row]:
    """W1: IPSO 20 × 2000, 32 full poses, 24 parameters (Wen 2019)."""
    prob, box = wen2019_problem(_compiled())

    def run(iterations=wen2019.IPSO["iterations"]):
        return ipso(lambda X: prob.objective(X), -box, box, **{**wen2019.IPSO, "iterations": iterations}, seed=0,
                    backend=_compiled())

    run(5)  # compile / warm caches outside the timing
    t = median_time(run, repeats)
    return [Row("W1 IPSO 20×2000, ER10L-C10 32 poses", t, "s", "≤ 0.3 s (paper: 220 s MATLAB)", t <= 0.3)]


def w1_naive_ratio(repeats: int = 3, label: str = "", target: float = 0.08) -> list[Row]:
    """W1 warm: robocal's IPSO (compiled kernels, loaded) beside a straightforward numpy IPSO of
    the same workload (:mod:`robocal.bench.naive`) and robocal's own numpy path, interleaved:
    the ratios of paired runs (target: ≤ 0.08 of the naive one quiet, ≤ 0.10 with one busy
    process per core)."""
    from . import naive

    prob, box = wen2019_problem(_compiled())
    plain_prob, _ = wen2019_problem("numpy")
    f, lo, hi = naive.wen2019(prob.k)

    def run(problem, backend, iterations=wen2019.IPSO["iterations"]):
        return ipso(lambda X: problem.objective(X), -box, box, **{**wen2019.IPSO, "iterations": iterations}, seed=0,
                    backend=backend).time_s

    if _compiled() != "numba":
        return [Row(f"W1 IPSO kernels / naive numpy{label}", float("nan"), "×", f"≤ {target:g}", None,
                    note="numba not installed (fast extra)")]
    run(prob, "numba", 5)
    run(plain_prob, "numpy", 5)
    compiled, plain, ref = [], [], []
    for _ in range(repeats):
        compiled.append(run(prob, "numba"))
        plain.append(run(plain_prob, "numpy"))
        ref.append(naive.ipso(f, lo, hi, **wen2019.IPSO, seed=0)[2])
    ratio = statistics.median(c / r for c, r in zip(compiled, ref))
    numpy_ratio = statistics.median(p / r for p, r in zip(plain, ref))
    return [Row(f"W1 IPSO 20×2000, numba kernels{label}", statistics.median(compiled), "s", "—", None),
            Row(f"W1 IPSO 20×2000, robocal's numpy path{label}", statistics.median(plain), "s", "—", None,
                note=f"{numpy_ratio:.2f}× the naive numpy IPSO"),
            Row(f"W1 IPSO 20×2000, naive numpy IPSO{label}", statistics.median(ref), "s", "—", None),
            Row(f"W1 time ratio kernels / naive numpy{label}", ratio, "×", f"≤ {target:g}", ratio <= target,
                note="median of paired runs")]


_FIRST_RUN = """
import json, time, warnings
warnings.simplefilter("ignore")
t0 = time.perf_counter()
from robocal.calibration import calibrate
from robocal.io.robotfile import load_robot
from robocal.presets import wen2019
from robocal.simulation import simulate
robot = load_robot("er10l-c10")
sim = simulate(robot, wen2019.POSES, deviations="paper", seed=1)
r = calibrate(robot, sim.measurements, "ipso", frames="none", seed=0)
print(json.dumps({"time_s": r.optimization.time_s, "compile_s": r.timings.get("compile_s", 0.0),
                  "wall_s": time.perf_counter() - t0}))
"""

_NAIVE = """
import json, warnings
warnings.simplefilter("ignore")
from robocal.bench import naive
from robocal.presets import wen2019
f, lo, hi = naive.wen2019({k!r})
print(json.dumps({{"time_s": naive.ipso(f, lo, hi, **wen2019.IPSO, seed=0)[2]}}))
"""


def w1_whole_process(repeats: int = 5) -> list[Row]:
    """W1 as a whole process, warm: ``robocal calibrate er10l-c10 DATA --method ipso`` (reading the
    32 poses, the swarm, the statistics, writing the result) beside the naive numpy IPSO's script
    (:data:`_NAIVE`), each a fresh interpreter, interleaved; the median of the paired ratios
    (target ≤ 0.5): start-up, imports and loading the compiled kernels are most of either."""
    import sys
    import tempfile

    from ..io.measurements import save_measurements

    prob, _ = wen2019_problem("numpy")
    with tempfile.TemporaryDirectory() as d:
        data = Path(d) / "w1.csv"
        save_measurements(simulate(load_robot("er10l-c10"), wen2019.POSES, deviations="paper", seed=1).measurements,
                          data)
        ours = [sys.executable, "-m", "robocal", "calibrate", "er10l-c10", str(data), "--method", "ipso", "--frames",
                "none", "--seed", "0", "--out", str(Path(d) / "w1.json"), "--quiet"]
        naive_cmd = [sys.executable, "-c", _NAIVE.format(k=prob.k)]
        _wall(ours), _wall(naive_cmd)  # the kernels loaded once, files in the page cache
        pairs = [(_wall(ours), _wall(naive_cmd)) for _ in range(repeats)]
    ratio = statistics.median(a / b for a, b in pairs)
    return [Row("W1 robocal calibrate --method ipso, whole process", statistics.median(a for a, _ in pairs), "s", "—",
                None),
            Row("W1 naive numpy IPSO script, whole process", statistics.median(b for _, b in pairs), "s", "—", None),
            Row("W1 time ratio whole processes, robocal / naive", ratio, "×", "≤ 0.5", ratio <= 0.5,
                note="median of paired runs")]


def w1_first_run(repeats: int = 3) -> list[Row]:
    """W1 as the first run after install meets it: ``calibrate(…, "ipso")`` in a fresh interpreter
    whose numba cache is empty (its own cache folder and temporary folder), beside the naive
    numpy IPSO in another, interleaved; the compile it starts in the background is ended after
    each.  time_s is the optimizer's own time; compiling and loading are reported apart."""
    import signal
    import subprocess
    import sys
    import tempfile

    prob, _ = wen2019_problem("numpy")
    first, naive_s = [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as d:
            env = {**os.environ, "NUMBA_CACHE_DIR": str(Path(d) / "cache"), "TMPDIR": d}
            out = subprocess.run([sys.executable, "-c", _FIRST_RUN], capture_output=True, text=True, check=True,
                                 env=env).stdout
            first.append(json.loads(out.splitlines()[-1]))
            for pid in (Path(d) / "cache").glob("robocal/compile-*/pid"):  # the background compile: not in the
                try:  # next timing
                    os.killpg(int(pid.read_text()), signal.SIGTERM)
                except (OSError, ValueError):
                    pass
        out = subprocess.run([sys.executable, "-c", _NAIVE.format(k=prob.k)], capture_output=True, text=True,
                             check=True).stdout
        naive_s.append(json.loads(out.splitlines()[-1])["time_s"])
    ratio = statistics.median(f["time_s"] / n for f, n in zip(first, naive_s))
    return [Row("W1 first run after install: calibrate ipso, time_s", statistics.median(f["time_s"] for f in first),
                "s", "—", None, note=f"compile/load {statistics.median(f['compile_s'] for f in first):.2f} s "
                f"apart, {statistics.median(f['wall_s'] for f in first):.2f} s in all"),
            Row("W1 first run, naive numpy IPSO", statistics.median(naive_s), "s", "—", None),
            Row("W1 first-run time ratio robocal / naive numpy", ratio, "×", "≤ 1.0", ratio <= 1.0,
                note="median of paired runs")]


class busy_cores:
    """One busy process per core in the background for the block (each a Python loop), so that a
    workload is timed as it runs beside other work; they are ended on exit."""

    def __init__(self, n: int | None = None):
        import os

        self.n = n or len(os.sched_getaffinity(0))
        self.procs = []

    def __enter__(self):
        import subprocess
        import sys

        self.procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(self.n)]
        time.sleep(0.5)  # let them take their cores
        return self

    def __exit__(self, *exc):
        for p in self.procs:
            p.kill()
        for p in self.procs:
            p.wait()
        return False


def w2_swarms(repeats: int = 5) -> list[Row]:
    """W2: PSO 240 × 500 against LDPSO-BT 240 → 40 × 500, 30 poses (Kou 2022), interleaved."""
    prob, box, _ = kou2022_problem()

    def f(X):
        return prob.objective(X, "sum_norms")

    pso(f, -box, box, **{**kou2022.PSO, "iterations": 3})
    ldpso_bt(f, -box, box, **{**kou2022.LDPSO_BT, "iterations": 3})
    tp, tl = [], []
    for i in range(repeats):
        tp.append(median_time(lambda i=i: pso(f, -box, box, **kou2022.PSO, seed=i), 1))
        tl.append(median_time(lambda i=i: ldpso_bt(f, -box, box, **kou2022.LDPSO_BT, seed=i), 1))
    p, ld = float(np.median(tp)), float(np.median(tl))
    ratio = float(np.median(np.array(tl) / np.array(tp)))
    return [
        Row("W2 PSO 240×500, KR5 arc 30 poses", p, "s", "", None),
        Row("W2 LDPSO-BT 240→40×500", ld, "s", "≤ 1 s", ld <= 1.0),
        Row("W2 ratio LDPSO-BT / PSO time (median of pairs)", ratio, "×", "≤ 0.62 (paper: 0.58)", ratio <= 0.62),
    ]


def _lm_calibration(robot, meas):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return calibrate(robot, meas, "lm")


LARGE_LM = """
import time, json, warnings
import numpy as np
from robocal.io.robotfile import load_robot
from robocal.simulation import simulate
from robocal.calibration import calibrate
robot = load_robot("er10l-c10")
sim = simulate(robot, {poses}, deviations="paper", seed=5, noise=0.02, angle_noise=np.radians(0.001))
t = time.perf_counter()
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    res = calibrate(robot, sim.measurements, "lm")
print(json.dumps({{"time_s": time.perf_counter() - t, "status": res.optimization.status,
                  "rms": res.metrics["after"].position["rms"]}}))
"""


def w3_lm(repeats: int = 5, large: bool = True) -> list[Row]:
    """W3: LM calibration (identifiability, LM, uncertainty, metrics) of 32, 1000 and 100 000 poses."""
    robot = load_robot("er10l-c10")
    rows = []
    for m, target in ((32, 0.020), (1000, 0.150)):
        sim = simulate(robot, m, deviations="paper", seed=1, noise=0.02, angle_noise=1e-5)
        _lm_calibration(robot, sim.measurements)
        t = median_time(lambda meas=sim.measurements: _lm_calibration(robot, meas), repeats)
        rows.append(Row(f"W3 LM calibration, {m} poses", t, "s", f"≤ {target * 1000:g} ms", t <= target))
    if large:
        out, peak = run_measured(LARGE_LM.format(poses=100_000))
        rows.append(Row("W3 LM calibration, 100000 poses", out["time_s"], "s", "≤ 10 s, < 2 GB",
                        out["time_s"] <= 10.0 and peak < 2.0,
                        note=f"peak resident memory {peak:.2f} GB (own process)"))
    return rows


def w4_fk(pairs: int = 1_000_000, repeats: int = 3) -> list[Row]:
    """W4: positions of ``pairs`` (particle, pose) pairs for a 6-joint robot, one batched call."""
    robot = load_robot("kr5-arc")
    space = ParameterSpace.of(robot)
    P = 1000
    rng = np.random.default_rng(0)
    geom, base, tools = space.expand(rng.normal(size=(P, space.size)) * 1e-3)
    q = rng.uniform(-2, 2, (pairs // P, 6))
    t_np = median_time(lambda: chain_points("dh", geom, q, base, tools[:, :1]), repeats)
    rows = [Row(f"W4 FK positions, {pairs:,} pairs, numpy", pairs / t_np / 1e6, "M/s", "≥ 2 M/s",
                pairs / t_np / 1e6 >= 2)]
    if _compiled() == "numba":
        from ..model import kernels

        constants, qt = kernels.chain_constants(geom), kernels.joint_trig(q)

        def compiled():
            return kernels.points(0, constants, base, tools[0, 0], qt)

        compiled()
        t_c = median_time(compiled, repeats)
        rows.append(Row(f"W4 FK positions, {pairs:,} pairs, numba", pairs / t_c / 1e6, "M/s", "≥ 10 M/s",
                        pairs / t_c / 1e6 >= 10))
    else:
        rows.append(Row("W4 FK positions, numba", float("nan"), "M/s", "≥ 10 M/s", None, note="numba not in use"))
    return rows


def w5_pkm(repeats: int = 5) -> list[Row]:
    """W5 (Chen 2023): the compensation PSO (100 × 200) for 30 targets at once, and FK of 10 000 rod sets."""
    from ..pkm.compensation import compensate_paper, planted
    from ..pkm.geometry import chen2023
    from ..pkm.kinematics import forward, ik, workspace_targets

    g = chen2023()
    real = g.with_errors(planted(1))
    q = workspace_targets(g, 30, seed=2)
    compensate_paper(g, real, q)
    t_pso = median_time(lambda: compensate_paper(g, real, q), repeats)
    L = ik(g, workspace_targets(g, 10_000, seed=3, angle=0.2))
    forward(g, L)
    t_fk = median_time(lambda: forward(g, L), repeats)
    return [
        Row("W5 eq. 18 PSO 100×200, 30 targets in one batch", t_pso, "s", "≤ 0.5 s", t_pso <= 0.5,
            note="includes driving and measuring the simulated machine"),
        Row("W5 PKM forward kinematics, 10 000 rod sets", t_fk, "s", "≤ 0.2 s", t_fk <= 0.2),
    ]


#: the real data of W6, in a source checkout
UR10_DATA = Path("examples") / "ur10-ipa" / "series_c.csv"


def half_split(data: Path, folder: Path, seed: int = 0) -> Path:
    """The calibration half of series C as the README splits it (examples/ur10-ipa/split.py:
    rows shuffled with the seed, the first half kept in file order), written to ``folder``, and the
    other half beside it (``validation.csv``)."""
    header, *rows = Path(data).read_text(encoding="utf-8").splitlines()
    order = np.random.default_rng(seed).permutation(len(rows))
    out = Path(folder) / "calibration.csv"
    for name, half in ((out, np.sort(order[: len(rows) // 2])), (out.with_name("validation.csv"),
                                                                  np.sort(order[len(rows) // 2:]))):
        name.write_text("\n".join([header, *(rows[i] for i in half)]) + "\n", encoding="utf-8")
    return out


def _command_line(data: Path, model: str, out: Path) -> float:
    """Wall time (s) of ``robocal calibrate ur10 DATA --frames base+tool --validate … --model MODEL``
    as a user runs it (the README's): a fresh interpreter, reading, calibrating, validating on the
    other half, reporting and writing."""
    import sys

    return _wall([sys.executable, "-m", "robocal", "calibrate", "ur10", str(data), "--frames", "base+tool",
                  "--validate", str(Path(data).with_name("validation.csv")), "--model", model, "--out", str(out)])


def _wall(cmd: list[str]) -> float:
    """Wall time (s) of a command run to its end (its output kept from the terminal)."""
    import subprocess

    start = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    return time.perf_counter() - start


def _without_workers(fn):
    """``fn()`` with ``ROBOCAL_WORKERS=1`` (every piece in this process), the variable restored after."""
    import os

    before = os.environ.get("ROBOCAL_WORKERS")
    os.environ["ROBOCAL_WORKERS"] = "1"
    try:
        return fn()
    finally:
        if before is None:
            del os.environ["ROBOCAL_WORKERS"]
        else:
            os.environ["ROBOCAL_WORKERS"] = before


def w6_auto(repeats: int = 1, data: Path = UR10_DATA) -> list[Row]:
    """W6: ``--model auto`` on the UR10 half split (1386 full poses, frames base+tool) beside a
    geometric LM calibration of the same poses, the two interleaved: on the command line (as a
    user runs them, validating on the other half; the ≤ 4× target is theirs) and as calls of the
    Python API in one process."""
    import tempfile

    from ..calibration.select.choice import learned_of
    from ..io.measurements import load_measurements

    if not Path(data).is_file():
        return [Row("W6 --model auto, UR10 half split", float("nan"), "s", "≤ 60 s", None,
                    note=f"needs {data} (run from the source tree)")]
    with tempfile.TemporaryDirectory() as folder:
        path = half_split(data, Path(folder))
        meas = load_measurements(path, n_joints=6)

        def run(model):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return calibrate("ur10", meas, "lm", frames="base+tool", model=model)

        run("geometric")  # imports and caches outside the timing
        _command_line(path, "geometric", Path(folder) / "warm.json")  # numba's cache on disk
        cli_geometric, cli_auto, geometric, auto, alone = [], [], [], [], []
        for _ in range(repeats):
            cli_geometric.append(_command_line(path, "geometric", Path(folder) / "g.json"))
            cli_auto.append(_command_line(path, "auto", Path(folder) / "a.json"))
            geometric.append(median_time(lambda: run("geometric"), 1))
            t = time.perf_counter()
            result = run("auto")
            auto.append(time.perf_counter() - t)
            alone.append(_without_workers(lambda: median_time(lambda: run("auto"), 1)))
        # the command line's model on the other half, as the README reports it
        validation = json.loads((Path(folder) / "a.json").read_text())["metrics"]["validation_after"]["position"]["rms"]
    tried = [r.model for r in result.model_selection]
    cli_ratio = statistics.median(a / g for a, g in zip(cli_auto, cli_geometric))
    ratio = statistics.median(a / g for a, g in zip(auto, geometric))
    t_auto = statistics.median(auto)
    return [
        Row(f"W6 --model auto, UR10 half split ({meas.n_poses} full poses)", t_auto, "s", "≤ 60 s", t_auto <= 60.0,
            note=f"chose {result.model}; {sum(not learned_of(m) for m in tried)} parametric models × 5 folds, "
                 f"{sum(bool(learned_of(m)) for m in tried)} learned corrections (processes, trees)"),
        Row("W6 --model auto without worker processes (ROBOCAL_WORKERS=1)", statistics.median(alone), "s", "—", None,
            note=f"the workers take {statistics.median(a / w for a, w in zip(alone, auto)):.2f}× less wall time"),
        Row("W6 geometric LM, same poses", statistics.median(geometric), "s", "—", None),
        Row("W6 time ratio auto / geometric, Python API", ratio, "×", "—", None, note="median of paired runs"),
        Row("W6 robocal calibrate --model auto", statistics.median(cli_auto), "s", "—", None),
        Row("W6 robocal calibrate --model geometric", statistics.median(cli_geometric), "s", "—", None),
        Row("W6 time ratio auto / geometric, command line", cli_ratio, "×", "≤ 4, validation ≤ 0.175 mm",
            cli_ratio <= 4.0 and validation <= 0.175,
            note=f"median of paired runs; auto's validation RMS {validation:.4f} mm on the other half"),
    ]


def _taught(robot_name: str, n: int, seed: int, tool: np.ndarray | None = None):
    """The controller's joints (n, 6) of poses a robot was taught at, at random 10° inside its limits,
    the poses (with ``tool``, else the robot's own) and their configuration facts."""
    from ..inverse.configuration import arm_configuration

    robot = load_robot(robot_name)
    lim = robot.limits + np.radians([10.0, -10.0])
    q = np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (n, robot.n_joints))
    arm = arm_configuration(robot, q)
    facts = [{"front": a, "elbow": b, "lower": c} for a, b, c in zip(arm.front.tolist(), arm.elbow.tolist(),
                                                                      arm.lower.tolist())]
    return robot.to_controller(q), (robot if tool is None else robot.with_tool(tool)).fk(q), facts


def rapid_module(n: int, seed: int = 0) -> str:
    """An IRB 120 module of ``n`` robtargets (tool ``gun``, 150 mm), taught at random joints inside
    the limits, each with its configuration data, reached by MoveL."""
    from scipy.spatial.transform import Rotation

    from ..filtering.rapid import encode

    tool = np.eye(4)
    tool[2, 3] = 150.0
    q, T, facts = _taught("irb120", n, seed, tool)
    quat = Rotation.from_matrix(T[:, :3, :3]).as_quat()
    lines = ["MODULE Cell", "  PERS tooldata gun:=[TRUE,[[0,0,150],[1,0,0,0]],[2,[0,0,50],[1,0,0,0],0,0,0]];"]
    for i in range(n):
        cf = encode(q[i], facts[i], {"cf1": 0, "cf4": 0, "cf6": 0, "cfx": 0})
        x, y, z, w = quat[i]
        lines.append(f"  CONST robtarget p{i}:=[[{T[i, 0, 3]:.3f},{T[i, 1, 3]:.3f},{T[i, 2, 3]:.3f}],"
                     f"[{w:.8f},{x:.8f},{y:.8f},{z:.8f}],[{cf['cf1']},{cf['cf4']},{cf['cf6']},{cf['cfx']}],"
                     "[9E9,9E9,9E9,9E9,9E9,9E9]];")
    lines += ["  PROC main()"] + [f"    MoveL p{i},v500,z10,gun;" for i in range(n)] + ["  ENDPROC", "ENDMODULE", ""]
    return "\n".join(lines)


_W7 = """
import json, tempfile, time, warnings
from pathlib import Path
import numpy as np
from robocal.bench.workloads import rapid_module
from robocal.filtering import filter_program
from robocal.io.robotfile import load_robot, save_robot
warnings.simplefilter("ignore")
n = {n}
folder = Path(tempfile.mkdtemp())
(folder / "cell.mod").write_text(rapid_module(n))
nominal = load_robot("irb120")
g = nominal.geometry.copy()
g[1, 0] += 0.4; g[3, 3] -= 0.3; g[1, 2] += 0.002; g[2, 1] -= 0.0015
save_robot(nominal.replace(geometry=g, name="planted"), folder / "cal.toml")
times = []
for _ in range({repeats}):
    t = time.perf_counter()
    result = filter_program(folder / "cal.toml", folder / "cell.mod", nominal)
    times.append(time.perf_counter() - t)
q = np.random.default_rng(1).uniform(-1, 1, (n, 6))
fk = []
for _ in range(5):
    t = time.perf_counter(); nominal.fk(q); fk.append(time.perf_counter() - t)
print(json.dumps({{"filter": float(np.median(times)), "fk": float(np.median(fk)), "counts": result.counts()}}))
"""


def w7_filter(repeats: int = 3, n: int = 10_000, label: str = "") -> list[Row]:
    """W7: filtering a RAPID module of ``n`` robtargets for an IRB 120 against a planted accurate
    model, in a fresh interpreter (its peak memory is the filter's), beside one batched FK of as
    many poses (target: under 5 s and 300 MB for 10 000)."""
    result, peak = run_measured(_W7.format(n=n, repeats=repeats))
    counts = ", ".join(f"{v} {k}" for k, v in result["counts"].items())
    return [Row(f"W7 filter {n} RAPID robtargets, IRB 120{label}", result["filter"], "s", "≤ 5 s, ≤ 0.3 GB",
                result["filter"] <= 5.0 and peak <= 0.3, note=f"{peak:.2f} GB peak; {counts}"),
            Row(f"W7 one batched FK of {n} poses{label}", result["fk"], "s", "—", None,
                note=f"filter / FK: {result['filter'] / result['fk']:.0f}×")]


_CLI = """
import json, sys, time, warnings
warnings.simplefilter("ignore")
from robocal.cli import main
t = time.perf_counter()
try:
    main({args!r})
except SystemExit:
    pass
print(json.dumps({{"s": time.perf_counter() - t}}))
"""


def w7_command_line(repeats: int = 3, n: int = 10_000) -> list[Row]:
    """W7 as a user runs it: ``robocal filter`` of a module of ``n`` robtargets (its default output:
    the flagged and the largest corrections) beside ``robocal evaluate`` of as many poses, each a
    fresh interpreter, interleaved; the filter's peak memory."""
    import tempfile

    from ..io.measurements import save_measurements

    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        (folder / "cell.mod").write_text(rapid_module(n))
        nominal = load_robot("irb120")
        g = nominal.geometry.copy()
        g[1, 0] += 0.4
        g[3, 3] -= 0.3
        from ..io.robotfile import save_robot

        save_robot(nominal.replace(geometry=g, name="planted"), folder / "cal.toml")
        save_measurements(simulate(nominal, n, seed=1, noise=0.01).measurements, folder / "poses.csv")
        filter_args = ["filter", str(folder / "cal.toml"), str(folder / "cell.mod"), "--nominal", "irb120", "--out",
                       str(folder / "out.mod")]
        evaluate_args = ["evaluate", str(folder / "cal.toml"), str(folder / "poses.csv")]
        filtered, evaluated, peaks = [], [], []
        for _ in range(repeats):
            result, peak = run_measured(_CLI.format(args=filter_args))
            filtered.append(result["s"])
            peaks.append(peak)
            evaluated.append(run_measured(_CLI.format(args=evaluate_args))[0]["s"])
    ratio = statistics.median(f / e for f, e in zip(filtered, evaluated))
    peak = max(peaks)
    return [Row(f"W7 robocal filter, {n} RAPID robtargets (default output)", statistics.median(filtered), "s",
                "≤ 0.3 GB", peak <= 0.3, note=f"{peak:.2f} GB peak"),
            Row(f"W7 robocal evaluate, {n} poses", statistics.median(evaluated), "s", "—", None),
            Row("W7 time ratio filter / evaluate, command line", ratio, "×", "≤ 3", ratio <= 3.0,
                note="median of paired runs")]


def program_files(language: str, n: int, seed: int = 0) -> dict[str, str]:
    """File name → text of a program of ``n`` Cartesian targets in ``language`` (``rapid``: IRB 120,
    :func:`rapid_module`; ``krl``: KR5 arc, E6POS in the .dat reached by PTP/LIN; ``fanuc``: LR Mate 200iD,
    P[n] of /POS; ``urscript``: UR10, PolyScope's waypoint pairs ``W_p``/``W_q``, movel and movej through
    get_inverse_kin), each target with its configuration data."""
    from ..math.so3 import matrix_to_rpy

    if language == "rapid":
        return {"cell.mod": rapid_module(n, seed)}
    if language == "krl":
        from ..filtering.krl import encode

        qc, T, facts = _taught("kr5-arc", n, seed)
        cba = np.degrees(matrix_to_rpy(T[:, :3, :3]))
        src, dat = ["DEF cell()", "  BAS(#INITMOV, 0)", "  BAS(#TOOL, 0)", "  BAS(#BASE, 0)"], ["DEFDAT cell"]
        for i in range(n):
            st = encode(qc[i], facts[i], {"S": 0, "T": 0})
            src.append(f"  {'PTP' if i % 2 else 'LIN'} XP{i + 1}")
            dat.append(f"  DECL E6POS XP{i + 1}={{X {T[i, 0, 3]:.3f},Y {T[i, 1, 3]:.3f},Z {T[i, 2, 3]:.3f},"
                       f"A {cba[i, 2]:.4f},B {cba[i, 1]:.4f},C {cba[i, 0]:.4f},S {st['S']},T {st['T']},E1 0.0,E2 0.0,"
                       "E3 0.0,E4 0.0,E5 0.0,E6 0.0}")
        return {"cell.src": "\r\n".join(src + ["END", ""]), "cell.dat": "\r\n".join(dat + ["ENDDAT", ""])}
    if language == "fanuc":
        from ..filtering.fanuc import encode

        qc, T, facts = _taught("lrmate200id", n, seed)
        wpr = np.degrees(matrix_to_rpy(T[:, :3, :3]))
        lines = ["/PROG  CELL", "/ATTR", "/MN"]
        lines += [f"{i + 1:4d}:{'J' if i % 2 else 'L'} P[{i + 1}] {'100%' if i % 2 else '500mm/sec'} FINE    ;"
                  for i in range(n)]
        lines.append("/POS")
        for i in range(n):
            c = encode(qc[i], facts[i], {"flip": "N", "elbow": "U", "side": "T", "t1": 0, "t4": 0, "t6": 0})
            lines += [f"P[{i + 1}]{{", "   GP1:",
                      f"\tUF : 0, UT : 0,\t\tCONFIG : '{c['flip']} {c['elbow']} {c['side']}, {c['t1']}, {c['t4']}, "
                      f"{c['t6']}',",
                      f"\tX = {T[i, 0, 3]:9.3f}  mm,\tY = {T[i, 1, 3]:9.3f}  mm,\tZ = {T[i, 2, 3]:9.3f}  mm,",
                      f"\tW = {wpr[i, 0]:9.3f} deg,\tP = {wpr[i, 1]:9.3f} deg,\tR = {wpr[i, 2]:9.3f} deg", "};"]
        return {"cell.ls": "\r\n".join(lines + ["/END", ""])}
    if language == "urscript":
        from scipy.spatial.transform import Rotation

        qc, T, _ = _taught("ur10", n, seed)
        rv = Rotation.from_matrix(T[:, :3, :3]).as_rotvec()
        lines = ["def cell():", "  set_tcp(p[0.0,0.0,0.0,0.0,0.0,0.0])"]
        for i in range(n):
            p = T[i, :3, 3] / 1000.0
            lines.append(f"  global W{i}_p=p[{p[0]:.12f}, {p[1]:.12f}, {p[2]:.12f}, {rv[i, 0]:.12f}, {rv[i, 1]:.12f}, "
                         f"{rv[i, 2]:.12f}]")
            lines.append(f"  global W{i}_q=[{', '.join(f'{v:.12f}' for v in qc[i])}]")
        lines += [f"  movej(get_inverse_kin(W{i}_p, qnear=W{i}_q), a=1.4, v=1.05)" if i % 2 else
                  f"  movel(W{i}_p, a=1.2, v=0.25)" for i in range(n)]
        return {"cell.script": "\n".join(lines + ["end", ""])}
    raise ValueError(f"no program generator for {language!r}")


def w7_languages(repeats: int = 3, n: int = 10_000) -> list[Row]:
    """W7's reading in each language: a program of ``n`` Cartesian targets (:func:`program_files`) read as
    ``robocal filter`` reads it (the cyclic collector held off), the median of ``repeats``; the time
    a target beside RAPID's.  (URScript's reading was quadratic in the program's length until it was
    measured here.)"""
    import gc
    import tempfile

    from ..filtering import load_program

    rows, rapid = [], None
    with tempfile.TemporaryDirectory() as d:
        for language in ("rapid", "krl", "fanuc", "urscript"):
            files = program_files(language, n)
            for name, text in files.items():
                (Path(d) / name).write_text(text)
            path = Path(d) / next(iter(files))
            was = gc.isenabled()
            gc.disable()
            try:
                times = []
                for _ in range(repeats):
                    t = time.perf_counter()
                    program = load_program(path)
                    times.append(time.perf_counter() - t)
            finally:
                if was:
                    gc.enable()
            s = statistics.median(times)
            rapid = rapid or s
            rows.append(Row(f"W7 read {n} targets, {language}", s, "s", "—", None,
                            note=f"{len(program.targets)} targets; {s / rapid:.2f}× RAPID's"))
    return rows


#: Universal Robots' published UR5 table (a, α, θ, d in mm and deg): the arm of W8
UR5_TOML = 'name = "UR5"\nconvention = "dh"\n' + "".join(
    f"[[joint]]\na = {a}\nalpha = {alpha}\ntheta = 0.0\nd = {d}\nlimits = [-360.0, 360.0]\n"
    for a, alpha, d in ((0.0, 90.0, 89.159), (-425.0, 0.0, 0.0), (-392.25, 0.0, 0.0), (0.0, 90.0, 109.15),
                        (0.0, -90.0, 94.65), (0.0, 0.0, 82.3)))


def ur5_campaign(n: int = 1000, seed: int = 0):
    """A UR5-sized position-only campaign (W8): the UR5 with deviations of a real arm's size (a, d
    within ±0.5 mm, α, θ within ±0.05°), a gear harmonic of joint 2 (0.02°) and gravity's sag of
    joints 2 and 3, measured at a reflector 33.7 mm along the flange axis with 0.02 mm noise;
    joints 1–4 over wide ranges, joint 5 ±3° about −90° and joint 6 ±3°: the wrist the poses see
    least, as on a grid scan."""
    from ..io.robotfile import parse_robot

    robot = parse_robot(UR5_TOML, source="UR5")
    rng = np.random.default_rng(seed)
    q = np.column_stack([rng.uniform(-1.5, 1.5, n), rng.uniform(-2.5, -0.6, n), rng.uniform(0.5, 2.2, n),
                         rng.uniform(-2.5, -0.5, n), -np.pi / 2 + rng.uniform(-0.05, 0.05, n),
                         rng.uniform(-0.05, 0.05, n)])
    deviations = {f"{k}{i}": float(rng.uniform(-0.5, 0.5)) for i in range(1, 7) for k in ("a", "d")}
    deviations |= {f"{k}{i}": float(rng.uniform(-1e-3, 1e-3)) for i in range(1, 7) for k in ("alpha", "theta")}
    sim = simulate(robot, n, q=q, deviations=deviations, noise=0.02, measure="position", seed=seed,
                   base=(1200.0, -300.0, 400.0, 0.0, 0.0, 0.3), tool=(0.0, 0.0, 33.7),
                   harmonics={2: [(np.radians(0.02), np.radians(-0.01))]}, compliance={2: 2e-5, 3: 3e-5})
    from dataclasses import replace

    return robot, replace(sim.measurements, torques=None)  # no torques logged: gravity's sag, as on most sets


def w8_auto_position(repeats: int = 1) -> list[Row]:
    """W8: ``--model auto`` on a UR5-sized position-only set (:func:`ur5_campaign`, 1000 poses)
    beside a geometric LM of the same poses, interleaved as Python calls in one process."""
    from ..calibration.select.choice import learned_of

    robot, meas = ur5_campaign()

    def run(model):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return calibrate(robot, meas, "lm", frames="base+tool", model=model)

    run("geometric")  # imports and caches outside the timing
    geometric, auto = [], []
    for _ in range(repeats):
        geometric.append(median_time(lambda: run("geometric"), 1))
        t = time.perf_counter()
        result = run("auto")
        auto.append(time.perf_counter() - t)
    tried = [r.model for r in result.model_selection]
    ratio = statistics.median(a / g for a, g in zip(auto, geometric))
    return [
        Row(f"W8 --model auto, UR5-sized position-only set ({meas.n_poses} poses)", statistics.median(auto), "s",
            "—", None, note=f"chose {result.model}; {sum(not learned_of(m) for m in tried)} parametric models, "
                            f"{sum(bool(learned_of(m)) for m in tried)} learned corrections"),
        Row("W8 geometric LM, same poses", statistics.median(geometric), "s", "—", None,
            note=f"held by the prior: {', '.join(result.held) or 'none'}"),
        Row("W8 time ratio auto / geometric", ratio, "×", "≤ 6", ratio <= 6.0, note="median of paired runs"),
    ]


WORKLOADS: dict[str, Callable[..., list[Row]]] = {"W1": w1_ipso, "W2": w2_swarms, "W3": w3_lm, "W4": w4_fk,
                                                  "W5": w5_pkm, "W6": w6_auto, "W7": w7_filter,
                                                  "W8": w8_auto_position}


def run_all(quick: bool = False, say: Callable[[str], None] = lambda s: None) -> list[Row]:
    """W1–W8, then W1's ratio to the numpy path, W6 and W7 again with one busy process per core;
    quick: fewer repeats, no 100 000-pose LM and no W6 or W8 (a minute each)."""
    reps = 3 if quick else 5
    rows: list[Row] = []
    for name, fn in WORKLOADS.items():
        if quick and name in ("W6", "W8"):
            continue
        say(f"running {name}")
        if name == "W3":
            rows += fn(reps, large=not quick)
        elif name == "W4":
            rows += fn(repeats=3)
        elif name in ("W6", "W8"):
            rows += fn()
        else:
            rows += fn(reps)
    say("running W1 beside the numpy path, quiet, and as whole processes")
    rows += w1_naive_ratio(3 if quick else 5) + w1_first_run(2 if quick else 3) + w1_whole_process(3 if quick else 5)
    if not quick:
        say("running W7 on the command line beside evaluate, and its reading in each language")
        rows += w7_command_line(3) + w7_languages(3)
    with busy_cores() as busy:
        say(f"running W1{'' if quick else ' and W6'} with {busy.n} busy processes in the background")
        rows += w1_naive_ratio(3 if quick else 5, label=f" ({busy.n} busy)", target=0.10)
        if not quick:
            rows += [Row(f"{r.workload} ({busy.n} busy)", r.value, r.unit, r.target, r.met, r.peer, r.note)
                     for r in w6_auto()]
        rows += w7_filter(1 if quick else 3, label=f" ({busy.n} busy)")
    return rows
