"""lpoe-calib: kinematic calibration of serial robots from laser-tracker measurements.

Local Product of Exponentials model (Gao et al. 2022); lengths in mm, angles in rad; numpy float64
arrays in and out. Every error raises ``lpoe.Error`` (a ``ValueError``): user input (the message
names the file and line), an argument of the wrong type and an unknown keyword argument (named).

The functions are the compiled module's (``lpoe._lpoe``) with their Python signatures made
explicit: ``inspect.signature(lpoe.calibrate)`` and ``help(lpoe.calibrate)`` show the keyword-only
arguments and their defaults (the tools' defaults, docs/python.md).
"""
import ast
import functools
import inspect
import numbers
import re

from . import _lpoe
from ._lpoe import *  # noqa: F401,F403
from ._lpoe import Calibration, Error, Model, Measurements  # noqa: F401


class _Default:
    """A default that is not a Python literal in the compiled signature, shown as written."""

    def __init__(self, text):
        self.text = text

    def __repr__(self):
        return self.text


def _split_top_level(text):
    """Splits a parameter list at the commas outside brackets."""
    items, depth, start = [], 0, 0
    for i, c in enumerate(text):
        if c in "[(":
            depth += 1
        elif c in "])":
            depth -= 1
        elif c == "," and depth == 0:
            items.append(text[start:i].strip())
            start = i + 1
    if text[start:].strip():
        items.append(text[start:].strip())
    return items


def _signature(function):
    """The signature pybind11 writes on the first line of the docstring, as an inspect.Signature
    (None for overloaded functions or an unexpected form)."""
    doc = getattr(function, "__doc__", None) or ""
    m = re.match(r"\s*(\w+)\((.*)\)(?:\s*->\s*(.*))?$", doc.split("\n", 1)[0])
    if not m:
        return None
    params, kind = [], inspect.Parameter.POSITIONAL_OR_KEYWORD
    try:
        for item in _split_top_level(m.group(2)):
            if item == "*":
                kind = inspect.Parameter.KEYWORD_ONLY
                continue
            if item.startswith("**"):
                params.append(inspect.Parameter(item[2:].split(":")[0].strip(),
                                                inspect.Parameter.VAR_KEYWORD))
                continue
            if item.startswith("*"):
                params.append(inspect.Parameter(item[1:].split(":")[0].strip(),
                                                inspect.Parameter.VAR_POSITIONAL))
                kind = inspect.Parameter.KEYWORD_ONLY
                continue
            name_type, _, default_text = item.partition(" = ")
            name, _, annotation = name_type.partition(":")
            default = inspect.Parameter.empty
            if default_text:
                try:
                    default = ast.literal_eval(default_text)
                except (ValueError, SyntaxError):
                    default = _Default(default_text)
            params.append(inspect.Parameter(
                name.strip(), kind, default=default,
                annotation=annotation.strip() or inspect.Parameter.empty))
        return inspect.Signature(params)
    except ValueError:
        return None


_SIMPLE_TYPES = {
    "int": lambda v: isinstance(v, numbers.Integral) and not isinstance(v, bool),
    "float": lambda v: isinstance(v, numbers.Real) and not isinstance(v, bool),
    "str": lambda v: isinstance(v, str),
    "bool": lambda v: isinstance(v, (bool, numbers.Integral)),
}


def _wrong_argument(signature, args, kwargs):
    """'name: cannot use str value 'many' (expected int)' for the first argument whose type does not
    fit its annotation; None when none is found (the compiled function's own message then)."""
    if signature is None:
        return None
    try:
        bound = signature.bind(*args, **kwargs)
    except TypeError:
        return None
    for name, value in bound.arguments.items():
        annotation = signature.parameters[name].annotation
        check = _SIMPLE_TYPES.get(annotation) if isinstance(annotation, str) else None
        if check is not None and not check(value):
            return (f"{name}: cannot use {type(value).__name__} value {value!r} (an argument has "
                    f"the wrong type: expected {annotation})")
    return None


def _wrap(function, qualname):
    """`function` with its explicit signature, checking the arguments against it first (an
    unknown keyword or a missing argument is lpoe.Error naming it) and turning the TypeError of an
    argument of the wrong type into lpoe.Error."""
    signature = _signature(function)

    @functools.wraps(function)
    def call(*args, **kwargs):
        if signature is not None:
            try:
                signature.bind(*args, **kwargs)
            except TypeError as e:
                known = [p.name for p in signature.parameters.values()
                         if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD) and p.name != "self"]
                unknown = [k for k in kwargs if k not in signature.parameters]
                if unknown:
                    raise Error(f"{qualname}: unknown option '{unknown[0]}' (options: "
                                f"{', '.join(known)})") from None
                raise Error(f"{qualname}: {e}") from None
        try:
            return function(*args, **kwargs)
        except TypeError as e:
            why = _wrong_argument(signature, args, kwargs)
            raise Error(f"{qualname}: {why or f'an argument has the wrong type: {e}'}") from None

    if signature is not None:
        call.__signature__ = signature
    del call.__wrapped__  # inspect.signature: the explicit one, not the compiled function's
    return call


def _wrap_module():
    for name in dir(_lpoe):
        if name.startswith("_"):
            continue
        obj = getattr(_lpoe, name)
        if type(obj).__name__ == "builtin_function_or_method":
            globals()[name] = _wrap(obj, f"lpoe.{name}")
        elif isinstance(obj, type) and not issubclass(obj, BaseException):
            for attr, member in list(vars(obj).items()):
                if type(member).__name__ != "instancemethod":
                    continue
                if attr.startswith("_") and attr != "__init__":
                    continue
                setattr(obj, attr, _wrap(member, f"lpoe.{name}.{attr}"))


_wrap_module()

__all__ = [name for name in dir() if not name.startswith("_")]
