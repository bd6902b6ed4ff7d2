"""Plain values read without pydantic.

Typer (0.2x, with its own click) turns every parameter's text into its value through a
pydantic ``TypeAdapter``: importing pydantic and building ~50 adapters costs about 0.1 s of
a command that may take 0.5 s in all.  Nearly all of robocal's parameters are plain text,
whole numbers, numbers, paths and lists of them, given in the usual spellings.  For those
values :func:`plain_coercion` gives typer a reader that returns what pydantic would (the
same ``int``/``float``/``Path``, tested against typer's own reader) and hands anything else,
or any other kind of parameter, to typer's own reader unchanged: an unusual spelling
(``1_000``, ``1.0`` for a whole number, a bound, an enum) gets typer's result and message.

Typer's reader is an internal interface (``typer._coercion``); where it is absent (an older
typer, which parses with click alone, or a newer one that changed it), nothing is changed.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, get_args, get_origin

# the spellings Python and pydantic read alike, to the bit: ASCII digits, no underscores,
# no surrounding space; an int of at most 18 digits (pydantic refuses past its limit)
_INT = re.compile(r"[+-]?[0-9]{1,18}")
_FLOAT = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_LEAVES = (str, int, float, bool, Path)


def _leaf(annotation: Any) -> Any:
    """The plain type that ``annotation`` (``T`` or ``list[T]``) holds, or None."""
    if get_origin(annotation) is list:
        args = get_args(annotation)
        annotation = args[0] if len(args) == 1 else None
    return annotation if annotation in _LEAVES else None


def _plain_info(info: Any) -> bool:
    """No parser, bound, clamp or path check beyond typer's defaults."""
    return (getattr(info, "parser", None) is None and getattr(info, "min", None) is None
            and getattr(info, "max", None) is None and not getattr(info, "clamp", False)
            and getattr(info, "path_type", None) is None)


_MISSING = object()


def _read(leaf: type, value: Any) -> Any:
    """``value`` as ``leaf``, or _MISSING where typer's own reader must decide."""
    if leaf is str:
        return value if isinstance(value, str) else _MISSING
    if leaf is bool:
        return value if isinstance(value, bool) else _MISSING
    if isinstance(value, bool):
        return _MISSING
    if leaf is int:
        if isinstance(value, int):
            return value
        return int(value) if isinstance(value, str) and _INT.fullmatch(value) else _MISSING
    if leaf is float:
        if isinstance(value, (int, float)):
            return float(value)
        return float(value) if isinstance(value, str) and _FLOAT.fullmatch(value) else _MISSING
    return value if isinstance(value, Path) else Path(value) if isinstance(value, str) else _MISSING


def plain_coercion(command: Any) -> None:
    """Give every plain parameter of ``command`` (a click command or group, recursively) the
    reader described in the module docstring; the others keep typer's."""
    try:
        from typer._coercion import RuntimeParam, build_runtime_param
        from typer._param_types import coerce_cli_path
    except ImportError:
        return

    class Plain(RuntimeParam):
        """Typer's coercion contract, for a plain leaf type or a list of one."""

        def _coerce_value(self, value, param, ctx):
            leaf = _leaf(self.annotation)
            items = value if isinstance(value, (list, tuple)) and leaf is not self.annotation else None
            read = [_read(leaf, v) for v in items] if items is not None else _read(leaf, value)
            if read is _MISSING or (items is not None and any(r is _MISSING for r in read)):
                return build_runtime_param(param.type_descriptor)._coerce_value(value, param, ctx)
            if leaf is Path:  # typer's own checks (readable, exists, …) on the path
                read = ([coerce_cli_path(r, self.parameter_info, path_type=Path, param=param, ctx=ctx) for r in read]
                        if items is not None else
                        coerce_cli_path(read, self.parameter_info, path_type=Path, param=param, ctx=ctx))
            if items is None and leaf is not self.annotation:  # a lone value for a list: pydantic lists it
                return [read]
            return read

    def visit(cmd: Any, parent: Any) -> None:
        # the --help option is made when a command is first parsed, and read like any other
        ctx = cmd.context_class(cmd, info_name=cmd.name, parent=parent, **cmd.context_settings)
        helps = [cmd.get_help_option(ctx)] if hasattr(cmd, "get_help_option") else []
        for param in [*getattr(cmd, "params", ()), *helps]:
            descriptor = getattr(param, "type_descriptor", None)
            if (getattr(param, "_runtime_param", _MISSING) is None and descriptor is not None
                    and descriptor.file_annotation is None and _leaf(descriptor.annotation) is not None
                    and _plain_info(descriptor.parameter_info)):
                param._runtime_param = Plain(descriptor.parameter_info, descriptor.annotation)
        for sub in getattr(cmd, "commands", {}).values():
            visit(sub, ctx)

    try:
        visit(command, None)
    except (AttributeError, TypeError):  # typer's internals changed shape: its own readers stay
        pass
