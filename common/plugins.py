"""Plug-ins: a class named by import path (`package.module:Class`) or by file (`path/to/file.py:Class`),
or by a name an installed package registers in an entry-point group (`drivestack.agents`,
`drivestack.controllers`). Loading one runs the user's code, by the user's choice; nothing here is
imported at start-up, and entry points are read only when a name is not built in."""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import inspect
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pydantic import BeforeValidator

AGENT_GROUP = "drivestack.agents"
CONTROLLER_GROUP = "drivestack.controllers"
FILE_SPEC = re.compile(r"(?P<file>.+\.py):(?P<name>[A-Za-z_]\w*)")
MODULE_SPEC = re.compile(r"(?P<module>[A-Za-z_]\w*(\.[A-Za-z_]\w*)*):(?P<name>[A-Za-z_]\w*)")
SPEC_FORMS = "module.path:ClassName or path/to/file.py:ClassName"


class PluginError(ValueError):
    """A plug-in that cannot be used; the message is one line for the user."""


class PluginFailed(RuntimeError):
    """A plug-in that raised or returned what its protocol rules out while the work ran; the
    message (one line) names the plug-in, the call and what came back."""


def failed_call(plugin: str, call: str, error: BaseException) -> PluginFailed:
    """`PluginFailed` for `plugin`'s `call` that raised `error`."""
    return PluginFailed(f"plug-in {plugin}: {call} raised {type(error).__name__}: {_first(error)}")


def bad_return(plugin: str, call: str, value: object, expected: str) -> PluginFailed:
    """`PluginFailed` for `plugin`'s `call` that returned `value` instead of `expected`."""
    return PluginFailed(f"plug-in {plugin}: {call} returned {repr(value)[:80]}; expected {expected}")


def is_spec(value: str) -> bool:
    """Whether `value` names a class by path (it has a colon) rather than by a registered name."""
    return ":" in value


def absolute_spec(spec: str) -> str:
    """`spec` with its file made absolute (a module path is returned as it is), so processes and
    Ray workers started elsewhere load the same file; PluginError when it fits neither form."""
    if match := FILE_SPEC.fullmatch(spec):
        try:
            return f"{Path(match['file']).expanduser().resolve()}:{match['name']}"
        except RuntimeError:
            raise PluginError(f"{spec[:120]!r}: no home directory for its '~'") from None
    if MODULE_SPEC.fullmatch(spec):
        return spec
    raise PluginError(f"{spec[:120]!r}: expected {SPEC_FORMS}")


def entry_points(group: str) -> dict[str, str]:
    """The names installed packages register in `group`, each with its `module:Class` value."""
    from importlib.metadata import entry_points as installed

    return {point.name: point.value for point in installed(group=group)}


def resolved(value: str, group: str) -> str:
    """The `module:Class` or absolute `file.py:Class` a plug-in name or spec stands for."""
    if is_spec(value):
        return absolute_spec(value)
    if (target := entry_points(group).get(value)) is None:
        raise PluginError(f"{value!r} is not installed in the entry-point group {group}")
    return absolute_spec(target)


def load_class(value: str, group: str) -> type:
    """The class `value` (a spec, or an entry-point name of `group`) names; PluginError (one line)
    when the module or file does not import or has no such class."""
    spec = resolved(value, group)
    module_name, _, class_name = spec.rpartition(":")
    try:
        module = _file_module(Path(module_name)) if module_name.endswith(".py") else _module(module_name)
    except PluginError:
        raise
    except (Exception, SystemExit) as error:  # noqa: BLE001 - user code may raise anything while importing
        raise PluginError(f"{value}: importing it failed: {type(error).__name__}: {_first(error)}") from None
    found = getattr(module, class_name, None)
    if not inspect.isclass(found):
        raise PluginError(f"{value}: {module_name} has no class {class_name}")
    return found


def _module(name: str) -> Any:
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as error:
        if error.name is None or not (name + ".").startswith(error.name + "."):
            raise
        local = f"{name.replace('.', '/')}.py"
        hint = f" (for the file here, write ./{local}:Class)" if Path(local).is_file() else ""
        raise PluginError(f"{name}: no module named {error.name}{hint}") from None


def _file_module(path: Path) -> Any:
    """The module of the Python file at `path`, imported once per process under a name derived from
    the absolute path (so two files of the same name stay apart, and pickling inside it works)."""
    if not path.is_file():
        raise PluginError(f"{path}: no such file")
    name = f"drivestack_plugin_{path.stem}_{hashlib.sha1(str(path).encode()).hexdigest()[:8]}"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise PluginError(f"{path}: not a Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


def construct(cls: type, offered: dict[str, Any], what: str) -> Any:
    """`cls` called with those of the `offered` keyword arguments its constructor names (all of
    them when it takes **kwargs); PluginError when it needs another or raises."""
    try:
        parameters = inspect.signature(cls).parameters
    except (TypeError, ValueError):
        parameters = {}  # type: ignore[assignment]
    takes_all = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values())
    needed = [
        name
        for name, p in parameters.items()
        if p.default is inspect.Parameter.empty
        and p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
        and name not in offered
    ]
    if needed:
        raise PluginError(
            f"{what}: its constructor needs {', '.join(needed)}; it may take only {', '.join(offered)}"
        )
    given = offered if takes_all else {k: v for k, v in offered.items() if k in parameters}
    try:
        return cls(**given)
    except (Exception, SystemExit) as error:  # noqa: BLE001 - user code may raise anything
        why = f"{type(error).__name__}: {_first(error)}"
        raise PluginError(f"{what}: constructing it failed: {why}") from None


def _first(error: BaseException) -> str:
    return (str(error).splitlines() or [""])[0][:160]


def checked_name(kind: str, builtins: tuple[str, ...], group: str, value: object) -> object:
    """`value` when it is a built-in name or an entry-point name of `group`, a class spec (a file
    spec made absolute); ValueError (one line) for anything else."""
    if not isinstance(value, str):
        raise ValueError(f"expected a {kind} name, got {repr(value)[:60]}")
    if value in builtins:
        return value
    if is_spec(value):
        return absolute_spec(value)
    installed = entry_points(group)
    if value in installed:
        return value
    options = ", ".join((*builtins, *installed))
    raise ValueError(f"unknown {kind} {repr(value)[:60]}; available: {options}, or {SPEC_FORMS}")


def plugin_name(kind: str, builtins: tuple[str, ...], group: str) -> BeforeValidator:
    """A pydantic validator for a field that takes what `checked_name` accepts."""
    from pydantic import BeforeValidator

    return BeforeValidator(lambda value: checked_name(kind, builtins, group, value))


def label(value: str) -> str:
    """A short name for tables and file names: a spec as `file.py:Class` or `module:Class`."""
    if is_spec(value):
        module, _, name = value.rpartition(":")
        return f"{Path(module).name if module.endswith('.py') else module}:{name}"
    return value


def short_labels(values: Sequence[str]) -> list[str]:
    """What figures and tables show for each of `values`: a built-in or entry-point name as it is,
    a plug-in by its class name, lengthened from the end of its path (`file.py:Class`,
    `folder/file.py:Class`, ..., for a module `module:Class`, `package.module:Class`, ...) only
    as far as it takes to tell it from the others; the results files keep the full names."""
    depths = [0] * len(values)
    while True:
        shown = [_shortened(value, depth) for value, depth in zip(values, depths, strict=True)]
        owners: dict[str, set[str]] = {}
        for text, value in zip(shown, values, strict=True):
            owners.setdefault(text, set()).add(value)
        longer = [
            index
            for index, text in enumerate(shown)
            if len(owners[text]) > 1 and _shortened(values[index], depths[index] + 1) != text
        ]
        if not longer:
            return shown
        for index in longer:
            depths[index] += 1


def _shortened(value: str, depth: int) -> str:
    """`value`'s class name after the last `depth` parts of its module path or file path."""
    if not is_spec(value):
        return value
    module, _, name = value.rpartition(":")
    parts = Path(module).parts if module.endswith(".py") else tuple(module.split("."))
    if depth == 0:
        return name
    if depth >= len(parts):
        return value
    return f"{('/' if module.endswith('.py') else '.').join(parts[-depth:])}:{name}"


def file_safe(value: str) -> str:
    """`label(value)` with every character a file name may not hold replaced by `_`; a plug-in's
    with a digest of its full name after it, so two files of one name stay apart."""
    digest = f"-{hashlib.sha1(value.encode()).hexdigest()[:8]}" if is_spec(value) else ""
    return re.sub(r"[^\w.-]", "_", label(value)) + digest
