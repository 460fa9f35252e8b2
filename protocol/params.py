"""Typed parameters, declared once.

A world or a program declares its parameters as a frozen dataclass; each field carries its type,
its default and a one-line doc, optionally a range or a set of choices::

    @dataclass(frozen=True)
    class GridWorldParams:
        size: int = option(9, "side of the square grid, in cells", min=3)
        actions: int = option(4, "moves per state", choices=(4, 8))

`parse(GridWorldParams, {"size": "7"}, name="gridworld")` builds an instance from `k=v` strings
(the command line) or already-typed values (Python callers, JSON configs): unknown keys are refused
with the valid ones listed and the closest suggested, values are cast by the declared type and
checked against the declared range and choices. Every failure is a `ParamError` (a ValueError)
whose message names the owner, the key and (a bounded prefix of) the value.

This is the one parser of world, perturbation and program parameters, and a strict one (what
Python's own `int`/`float` would let through is not a number here): ASCII digits only, no
underscores (`1_0`), no `inf`/`nan`, no float that underflows to 0 (`1e-400`); booleans exactly
`true/false/yes/no/on/off/1/0` and none exactly `none/null`, lowercase (`TRUE` is refused); a
value of at most `MAX_VALUE_CHARS` characters (a number: `MAX_NUMBER_CHARS`); a key given twice in
one set of `k=v` items is refused. `table_text` and `table_markdown` render the
declarations for `--list-params` and the README, so documentation cannot drift from the code.

Pure Python (plus rapidfuzz for suggestions): importable by `agent` and `worlds` alike.
"""

from __future__ import annotations

import dataclasses
import math
import re
import types
import typing
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Any, TypeVar

from rapidfuzz import fuzz, process

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

__all__ = [
    "MAX_NUMBER_CHARS",
    "MAX_VALUE_CHARS",
    "ParamError",
    "ParamInfo",
    "option",
    "parse",
    "quote",
    "cast_values",
    "assignments",
    "describe",
    "table_text",
    "table_markdown",
    "format_value",
    "suggest",
    "unknown_name",
]

P = TypeVar("P", bound="DataclassInstance")

_TRUE = ("true", "1", "yes", "on")
_FALSE = ("false", "0", "no", "off")
_NONE = ("none", "null")
MAX_VALUE_CHARS = 1024  # characters of one value (a name, a path, a list of numbers)
MAX_NUMBER_CHARS = 64  # characters of one number (a float needs 24 at most to be exact)
QUOTE_CHARS = 40  # characters of an offending value (or key) an error message quotes at most
_INT = re.compile(r"[+-]?[0-9]+")
_FLOAT = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_MANTISSA_NONZERO = re.compile(r"^[+-]?[0.]*[1-9]")


def quote(raw: Any) -> str:
    """`raw` as an error message shows it: its repr, cut to QUOTE_CHARS characters with a note of
    how long it was (a 100 KB value must not come back in the error)."""
    text = raw if isinstance(raw, str) else repr(raw)
    if len(text) <= QUOTE_CHARS:
        return repr(raw)
    return f"{text[:QUOTE_CHARS]!r}... ({len(text)} characters)"


class ParamError(ValueError):
    """A parameter that is unknown, does not parse as its declared type, or is out of range."""


def option(
    default: Any,
    doc: str,
    *,
    min: float | None = None,
    max: float | None = None,  # noqa: A002
    choices: Iterable[Any] | None = None,
) -> Any:
    """A dataclass field with its default, one-line doc and optional inclusive range or choices.

    Equivalent to ``field(default=default, metadata={"doc": doc, "min": min, ...})``; either form is
    read by `parse` and the table renderers.

    Parameters
    ----------
    default : object
        The default value (immutable: the dataclasses are frozen and shared).
    doc : str
        One line for `--list-params` and the README.
    min, max : float or None, default=None
        Inclusive bounds, checked by `parse`.
    choices : iterable or None, default=None
        The only values accepted.

    Returns
    -------
    dataclasses.Field
        Typed as Any so that it can be assigned to an annotated field.

    Examples
    --------
    >>> from dataclasses import dataclass
    >>> @dataclass(frozen=True)
    ... class P:
    ...     size: int = option(5, "side of the grid", min=2)
    >>> parse(P, ["size=7"]).size
    7
    """
    meta: dict[str, Any] = {"doc": doc}
    if min is not None:
        meta["min"] = min
    if max is not None:
        meta["max"] = max
    if choices is not None:
        meta["choices"] = tuple(choices)
    return dataclasses.field(default=default, metadata=meta)


@dataclasses.dataclass(frozen=True)
class ParamInfo:
    """One declared parameter, as shown by `--list-params` and the README.

    Attributes
    ----------
    name, type, default : str
        The field's name, its type and its default, as written on the command line.
    doc : str
        The field's doc, with its range or choices.
    """

    name: str
    type: str
    default: str
    doc: str


# types -----------------------------------------------------------------------------------------


def _hints(cls: type) -> dict[str, Any]:
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
        raise TypeError(f"{cls!r} is not a parameter dataclass")
    return typing.get_type_hints(cls)


def _optional(tp: Any) -> tuple[Any, bool]:
    """(the type inside Optional[...], whether None is allowed)."""
    origin = typing.get_origin(tp)
    if origin is typing.Union or origin is types.UnionType:
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(tp)) == 2:
            return args[0], True
        raise TypeError(f"unsupported parameter type {tp!r}")
    return tp, False


def _tuple_args(tp: Any) -> tuple[Any, int | None] | None:
    """(element type, fixed length or None for tuple[X, ...]) if `tp` is a tuple type."""
    if typing.get_origin(tp) is not tuple:
        return None
    args = typing.get_args(tp)
    if len(args) == 2 and args[1] is Ellipsis:
        return args[0], None
    if args and all(a is args[0] for a in args):
        return args[0], len(args)
    raise TypeError(f"unsupported parameter type {tp!r}: use tuple[X, ...] or tuple[X, X]")


def _type_name(tp: Any) -> str:
    inner, opt = _optional(tp)
    tup = _tuple_args(inner)
    if tup is not None:
        elem, n = tup
        name = ",".join([elem.__name__] * n) if n else f"{elem.__name__},..."
    else:
        name = inner.__name__
    return f"{name} | none" if opt else name


_ARTICLE = {"int": "an int", "float": "a float", "bool": "a bool (true/false/yes/no/on/off/1/0)", "str": "a str"}


def _expected(tp: Any) -> str:
    inner, opt = _optional(tp)
    tup = _tuple_args(inner)
    if tup is not None:
        elem, n = tup
        what = f"{n} comma-separated {elem.__name__}s" if n else f"comma-separated {elem.__name__}s"
    else:
        what = _ARTICLE.get(inner.__name__, f"a {inner.__name__}")
    return f"{what} or none" if opt else what


class _Why(ValueError):
    """A value refused for a reason beyond its type (the message says which)."""


class _TooLong(_Why):
    """A value over its length limit."""


def _number_text(raw: str) -> str:
    s = raw.strip()
    if len(s) > MAX_NUMBER_CHARS:
        raise _TooLong(f"has {len(s)} characters, a number at most {MAX_NUMBER_CHARS}")
    return s


def _scalar(raw: Any, tp: type) -> Any:
    """Cast one value to int, float, bool or str, strictly (see the module doc); raise ValueError
    when it does not fit (with a reason, when there is more to say than its type)."""
    if isinstance(raw, str) and len(raw) > MAX_VALUE_CHARS:
        raise _TooLong(f"has {len(raw)} characters, at most {MAX_VALUE_CHARS}")
    if tp is bool:
        if isinstance(raw, bool):
            return raw
        if isinstance(raw, int) and raw in (0, 1):
            return bool(raw)
        if isinstance(raw, str):
            s = raw.strip()
            if s in _TRUE:
                return True
            if s in _FALSE:
                return False
        raise ValueError
    if tp is int:
        if isinstance(raw, bool):
            raise ValueError
        if isinstance(raw, int):
            return raw
        if isinstance(raw, float) and raw.is_integer():
            return int(raw)
        if isinstance(raw, str):
            s = _number_text(raw)
            if _INT.fullmatch(s):
                return int(s)
        raise ValueError
    if tp is float:
        if isinstance(raw, bool):
            raise ValueError
        if isinstance(raw, (int, float)):
            v = float(raw)
        elif isinstance(raw, str):
            s = _number_text(raw)
            if not _FLOAT.fullmatch(s):
                raise ValueError
            v = float(s)
            if v == 0.0 and _MANTISSA_NONZERO.match(s):
                raise _Why("underflows to 0 (a float's smallest magnitude is about 5e-324)")
        else:
            raise ValueError
        if not math.isfinite(v):
            raise _Why("is not finite")
        return v
    if tp is str:
        if isinstance(raw, str):
            return raw
        raise ValueError
    raise TypeError(f"unsupported parameter type {tp!r}")


def _cast(raw: Any, tp: Any) -> Any:
    inner, opt = _optional(tp)
    if isinstance(raw, str) and len(raw) > MAX_VALUE_CHARS:
        raise _TooLong(f"has {len(raw)} characters, at most {MAX_VALUE_CHARS}")
    if opt and (raw is None or (isinstance(raw, str) and raw.strip() in _NONE)):
        return None
    tup = _tuple_args(inner)
    if tup is None:
        return _scalar(raw, inner)
    elem, n = tup
    if isinstance(raw, str):
        text = raw.strip()
        if len(text) >= 2 and (text[0], text[-1]) in (("(", ")"), ("[", "]")):
            text = text[1:-1]  # Python-style "(1, 2)" or "[1, 2]"
        items: list[Any] = [x.strip() for x in text.split(",")] if text.strip() else []
        if items and items[-1] == "" and len(items) > 1:
            items.pop()  # a trailing comma, as in "(0.1,)"
    elif isinstance(raw, (list, tuple)):
        items = list(raw)
    else:
        raise ValueError
    if n is not None and len(items) != n:
        raise ValueError
    return tuple(_scalar(x, elem) for x in items)


def _check(value: Any, meta: Mapping[str, Any]) -> str | None:
    """Why `value` breaks the declared range or choices, or None."""
    choices = meta.get("choices")
    if choices is not None and value is not None and value not in choices:
        return "is not one of " + ", ".join(format_value(c) for c in choices)
    lo, hi = meta.get("min"), meta.get("max")
    if value is None or (lo is None and hi is None):
        return None
    for v in value if isinstance(value, tuple) else (value,):
        if lo is not None and v < lo:
            return f"is below the minimum {format_value(lo)}"
        if hi is not None and v > hi:
            return f"is above the maximum {format_value(hi)}"
    return None


# parsing ---------------------------------------------------------------------------------------


def assignments(items: Iterable[str] | None, what: str = "--param") -> dict[str, str]:
    """`["k=v", ...]` as a dict; a ParamError for an item without '=' and for a key given twice
    (which of the two was meant cannot be guessed)."""
    out: dict[str, str] = {}
    for item in items or ():
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise ParamError(f"{what} expects key=value, got {quote(item)}")
        key = key.strip()
        if key in out:
            raise ParamError(
                f"{what} {quote(key)} is given twice ({quote(out[key])} and {quote(value.strip())}): give it once"
            )
        out[key] = value.strip()
    return out


def suggest(key: str, valid: Iterable[str]) -> str | None:
    """The valid name closest to a mistyped `key` (rapidfuzz ratio >= 60), or None."""
    valid = list(valid)
    best = process.extractOne(key, valid, scorer=fuzz.ratio, score_cutoff=60) if valid else None
    return best[0] if best else None


def unknown_name(what: str, key: str, valid: Iterable[str]) -> str:
    """ "unknown WHAT 'KEY' (did you mean 'X'?); valid: a, b, c", for refusing a name."""
    valid = list(valid)
    best = suggest(key, valid)
    hint = f" (did you mean {best!r}?)" if best else ""
    return f"unknown {what} {quote(key)}{hint}; valid: {', '.join(valid) if valid else '(none)'}"


def cast_values(cls: type, values: Mapping[str, Any] | Iterable[str] | None, name: str | None = None) -> dict[str, Any]:
    """Validate and cast only the given values: `{key: typed value}`.

    All problems are collected into one ParamError, so a command line is fixed in one go. Useful
    where the overrides themselves are kept (a daemon's JSON config) rather than a full instance.

    Parameters
    ----------
    cls : type
        The parameter dataclass that declares the fields.
    values : mapping, iterable of str, or None
        A mapping of strings or typed values, or an iterable of ``k=v`` strings.
    name : str or None, default=None
        Who owns the parameters, for messages (default: the class name).

    Returns
    -------
    dict of str to object
        The given keys only, with values of the declared types.

    Raises
    ------
    ParamError
        Naming every unknown key (with a suggestion), unparsable value and value out of range.
    TypeError
        If `cls` is not a dataclass.

    Examples
    --------
    >>> from sensorimotor.worlds.gridworld import GridWorldParams
    >>> cast_values(GridWorldParams, ["size=7"])
    {'size': 7}
    """
    owner = name or cls.__name__
    hints = _hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    if values is None:
        values = {}
    elif not isinstance(values, Mapping):
        values = assignments(values)
    out: dict[str, Any] = {}
    problems: list[str] = []
    for key, raw in values.items():
        if key not in fields:
            problems.append(f"{owner}: " + unknown_name("parameter", str(key), fields))
            continue
        tp = hints[key]
        try:
            value = _cast(raw, tp)
        except _Why as e:
            problems.append(f"{owner}: {key}={quote(raw)} {e}")
            continue
        except (ValueError, TypeError, OverflowError):
            problems.append(f"{owner}: {key}={quote(raw)} is not {_expected(tp)}")
            continue
        why = _check(value, fields[key].metadata)
        if why:
            problems.append(f"{owner}: {key}={quote(raw)} {why}")
            continue
        out[key] = value
    if problems:
        raise ParamError("; ".join(problems))
    return out


def parse(
    cls: type[P],
    values: Mapping[str, Any] | Iterable[str] | None = None,
    *,
    name: str | None = None,
    base: P | None = None,
) -> P:
    """An instance of the parameter dataclass `cls`: `base` with `values` cast, checked and applied.

    Parameters
    ----------
    cls : type
        The parameter dataclass (frozen, fields declared with `option`).
    values : mapping, iterable of str, or None, default=None
        Overrides: a mapping of strings or typed values, or an iterable of ``k=v`` strings.
    name : str or None, default=None
        Who owns the parameters, for messages (default: the class name).
    base : instance of `cls` or None, default=None
        The values to start from (default: all defaults).

    Returns
    -------
    instance of `cls`

    Raises
    ------
    ParamError
        With a message naming `name`, for every unknown, unparsable or out-of-range value.
    TypeError
        If `base` is not an instance of `cls`.

    Examples
    --------
    >>> from sensorimotor.worlds.gridworld import GridWorldParams
    >>> p = parse(GridWorldParams, {"size": "7"}, name="gridworld")
    >>> p.size
    7
    >>> parse(GridWorldParams, ["sise=7"], name="gridworld")  # doctest: +IGNORE_EXCEPTION_DETAIL
    Traceback (most recent call last):
    ...
    ParamError: gridworld: unknown parameter 'sise' (did you mean 'size'?); valid: size, barrier, actions, goal, max_episode_steps
    """
    typed = cast_values(cls, values, name)
    if base is None:
        return cls(**typed)
    if not isinstance(base, cls):
        raise TypeError(f"base must be a {cls.__name__}, got {type(base).__name__}")
    return dataclasses.replace(base, **typed)


# rendering -------------------------------------------------------------------------------------


def format_value(v: Any) -> str:
    """A value as it would be written on the command line (true, none, 1,2, 0.005)."""
    if v is None:
        return "none"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)  # the shortest string that parses back to the same float
    if isinstance(v, tuple):
        return ",".join(format_value(x) for x in v)
    return str(v)


def as_strings(params: Any) -> dict[str, str]:
    """Every field of a parameter instance as the k=v string it parses back from (exactly): how
    parameters travel in events and checkpoints."""
    return {f.name: format_value(getattr(params, f.name)) for f in dataclasses.fields(params)}


def describe(cls: type) -> list[ParamInfo]:
    """Every declared parameter of `cls`: name, type, default and doc (with its range or choices)."""
    hints = _hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        default = (
            f.default
            if f.default is not dataclasses.MISSING
            else (f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
        )
        doc = str(f.metadata.get("doc", ""))
        extra = []
        if "choices" in f.metadata:
            extra.append("one of " + "|".join(format_value(c) for c in f.metadata["choices"]))
        lo, hi = f.metadata.get("min"), f.metadata.get("max")
        if lo is not None and hi is not None:
            extra.append(f"{format_value(lo)}..{format_value(hi)}")
        elif lo is not None:
            extra.append(f">= {format_value(lo)}")
        elif hi is not None:
            extra.append(f"<= {format_value(hi)}")
        if extra:
            doc = f"{doc} ({'; '.join(extra)})" if doc else "; ".join(extra)
        out.append(ParamInfo(f.name, _type_name(hints[f.name]), format_value(default), doc))
    return out


def table_text(cls: type, title: str | None = None) -> str:
    """The parameters of `cls` as an aligned plain-text table (for `--list-params`)."""
    rows = [("name", "type", "default", "doc")] + [(p.name, p.type, p.default, p.doc) for p in describe(cls)]
    if len(rows) == 1:
        body = "  (no parameters)"
    else:
        widths = [max(len(r[i]) for r in rows) for i in range(3)]
        body = "\n".join(
            "  " + "  ".join(c.ljust(w) for c, w in zip(r[:3], widths, strict=True)) + "  " + r[3] for r in rows
        )
    return f"{title}\n{body}" if title else body


def _md(s: str) -> str:
    return s.replace("|", "\\|")


def table_markdown(cls: type) -> str:
    """The parameters of `cls` as a Markdown table (for the README)."""
    infos = describe(cls)
    if not infos:
        return "_no parameters_"
    lines = ["| name | type | default | doc |", "|---|---|---|---|"]
    lines += [f"| `{p.name}` | {_md(p.type)} | `{p.default}` | {_md(p.doc)} |" for p in infos]
    return "\n".join(lines)
