"""How every command's --help reads: options in panels by what they are about, a placeholder that
says what a value is (FILE, NUMBER, N, TEXT; none for a flag), and help texts shown as written.

Typer renders help with rich markup, where "[prior]" or "[gravity]" (a robot file's tables) would be
taken as tags and vanish; and it names an option's value by its Python type ("<list[Path]>").  One
walk over the click commands, before they run, settles all three for every command at once.
"""

from __future__ import annotations

from pathlib import Path

#: the panel each option goes in, by its parameter name; the rest stay in "Options"
PANELS = {
    "Data": ("validate", "column", "joint_unit", "length_unit", "delimiter", "decimal", "euler", "base_link",
             "tip_link", "exclude", "exclude_file", "point_distance", "distance_sigma", "row_order", "cameras",
             "camera", "camera_pose", "camera_poses", "markers", "payload", "position_only", "tool", "user_frame",
             "controller_frames", "nominal", "images", "joints"),
    "Model and fit": ("method", "frames", "seed", "params", "objective", "noise", "angle_noise", "k", "instrument",
                      "loss", "f_scale", "model", "harmonics", "prior", "pixel_noise", "uncertainty"),
    "Swarm": ("particles", "iterations", "box", "halton", "backend"),
    "Output": ("out", "export", "report", "poses_out", "map_over", "as_json", "require", "quiet", "summary", "truth",
               "markers_out", "verbose", "fmt"),
}
_PANEL_OF = {name: panel for panel, names in PANELS.items() for name in names}
#: a command with at most this many options keeps them in one panel
FEW = 8


def _placeholder(param) -> str:
    """What a value is: FILE (a path), N (a whole number), NUMBER, TEXT; a flag takes none.  Read
    from the annotation typer keeps (its click may be its own)."""
    from typing import get_args, get_origin

    kind = param.type_descriptor.annotation
    if get_origin(kind) is list:
        kind = get_args(kind)[0]
    if getattr(param, "is_flag", False) or kind is bool:
        return ""
    name = "FILE" if isinstance(kind, type) and issubclass(kind, Path) else "N" if kind is int else \
        "NUMBER" if kind is float else "TEXT"
    return f"{name}..." if param.nargs == -1 else name


def _flag_help(command, panel: bool) -> None:
    """--help shown as the flag it is (no placeholder), in the Output panel where there are panels."""
    own = command.get_help_option

    def help_option(ctx):
        option = own(ctx)
        if option is not None:
            option.metavar = ""
            option.rich_help_panel = "Output" if panel else None
        return option

    command.get_help_option = help_option


def tidy(command) -> None:
    """Every command below ``command`` (a click group) made to read as the module docstring says."""
    from rich.markup import escape

    if command.help:
        command.help = escape(command.help)
    if hasattr(command, "commands"):  # a group: its own options (--version, --help), then its commands
        for param in command.params:
            param.metavar = _placeholder(param)
        _flag_help(command, False)
        for sub in command.commands.values():
            tidy(sub)
        return
    options = [p for p in command.params if p.param_type_name == "option"]
    if len(options) > FEW:  # the panels in the order of PANELS: data first, output last
        rank = {panel: i for i, panel in enumerate(PANELS)}
        options.sort(key=lambda p: rank.get(_PANEL_OF.get(p.name, ""), len(rank) - 1.5))
        command.params = [p for p in command.params if p.param_type_name != "option"] + options
    _flag_help(command, len(options) > FEW)
    for param in command.params:
        if getattr(param, "help", None):
            param.help = escape(param.help)
        shown = _placeholder(param)
        if param.param_type_name == "option":
            param.metavar = shown
            if len(options) > FEW:
                param.rich_help_panel = _PANEL_OF.get(param.name, "Options")
        else:  # an argument's type column: its placeholder, not its Python type
            param.display_type_rich = lambda ctx, shown=shown: shown
