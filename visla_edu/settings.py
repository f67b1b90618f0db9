"""Declared settings: what each field of a configuration dataclass accepts, in one place.

:class:`~visla_edu.filters.FilterConfig` and :class:`~visla_edu.smoother.SmootherConfig` declare
every field with :func:`setting`, which stores a :class:`SettingSpec` in its metadata. The spec
checks a value given in Python (:func:`check_settings`, from ``__post_init__``), parses one given
as text (:func:`parse_setting`, for ``visla-edu run --set`` and ``--smoother-set``) and says what
is valid for ``--help`` (:meth:`SettingSpec.describe`, :func:`format_value`):

* booleans are ``true/false``, ``1/0``, ``yes/no`` (any case); anything else is an error;
* integers are integer literals (``2``, not ``2.5`` or ``2.0``);
* numbers are finite (``nan``, ``inf`` and overflowing literals like ``1e400`` are refused);
* a value outside its range is refused with the range and the reason, never clipped;
* ``none`` sets an optional field to None; a declared word (``auto``) is accepted as is.
"""

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["SettingSpec", "setting", "specs", "check_settings", "parse_setting", "parse_settings", "format_value"]

#: Key of the :class:`SettingSpec` in a dataclass field's metadata.
SPEC = "visla_edu.setting"

_TRUE, _FALSE = ("true", "1", "yes"), ("false", "0", "no")


@dataclass(frozen=True)
class SettingSpec:
    """What one setting accepts; ``kind`` is ``float``, ``int``, ``bool`` or ``str``.

    ``low``, ``high``: the plausible range (None: unbounded on that side), ``low_open``: the range
    excludes ``low``; ``words``: text values accepted as they are (e.g. ``("auto",)``; for ``str``
    settings, empty means any text, checked where it is used); ``optional``: None is allowed (``none``
    on the command line); ``per_axis``: a number setting also taking three, one per body axis, each in
    range (``0.1,0.02,0.02``); ``unit``, ``why``: for messages, the unit of the value and why the range
    is what it is; ``default``: the field's default (what ``--help`` shows).
    """

    kind: type
    low: float = None
    high: float = None
    low_open: bool = False
    words: tuple = ()
    optional: bool = False
    unit: str = ""
    why: str = ""
    per_axis: bool = False
    default: object = None

    def describe(self):
        """What is valid, e.g. ``"a number in (0.001, 100] px"`` or ``"an integer in [-2, 2] or 'auto'"``."""
        if self.kind is bool:
            text = "true or false (also 1/0, yes/no)"
        elif self.kind is str:
            text = "one of " + ", ".join(repr(w) for w in self.words) if self.words else "a text"
        else:
            noun = "an integer" if self.kind is int else "a number"
            text = noun + _range_text(self.low, self.high, self.low_open) + (f" {self.unit}" if self.unit else "")
            if self.per_axis:
                text += " (or three, x, y, z)"
            text += "".join(f" or {w!r}" for w in self.words)
        return text + (" or none" if self.optional else "")

    def check(self, name, value):
        """``value`` if valid (an integral float becomes an int for int settings), else ValueError.

        The message is ``"<name> must be <what is valid> (<why>), got <value>"``.
        """
        if value is None and self.optional or (isinstance(value, str) and value in self.words):
            return value
        if self.per_axis and isinstance(value, (tuple, list, np.ndarray)) and np.ndim(value) == 1 and len(value) == 3:
            return tuple(self._check_one(name, v, value) for v in value)
        return self._check_one(name, value, value)

    def _check_one(self, name, value, shown):
        """One number (or value) of the setting, checked; ``shown`` is what the message quotes."""
        ok, value = _coerce(self.kind, value)
        if ok and self.kind in (int, float):
            ok = math.isfinite(value) and _in_range(value, self.low, self.high, self.low_open)
        if not ok or (self.kind is str and self.words and value not in self.words):
            why = f" ({self.why})" if self.why else ""
            raise ValueError(f"{name} must be {self.describe()}{why}, got {_shown(shown)!r}")
        return value

    def parse(self, name, text):
        """The value of ``text`` as given on the command line, checked; ValueError naming the setting."""
        word = text.strip()
        if self.optional and word.lower() == "none":
            return None
        if word.lower() in self.words:
            return word.lower()
        try:
            parts = word.split(",") if self.per_axis and "," in word else [word]
            if len(parts) not in (1, 3):
                raise ValueError(word)
            values = [_from_text(self.kind, part.strip()) for part in parts]
            value = values[0] if len(values) == 1 else tuple(values)
        except ValueError:
            why = f"; {self.why}" if self.why else ""
            article = "an" if self.kind is int else "a"
            raise ValueError(f"{name} needs {article} {self.kind.__name__} ({self.describe()}{why}), "
                             f"got {text!r}") from None
        return self.check(name, value)


def setting(default, kind, low=None, high=None, *, low_open=False, words=(), optional=False, unit="", why="",
            per_axis=False):
    """A dataclass field with its :class:`SettingSpec`: ``dataclasses.field(default=default)``, spec in its metadata.

    The spec is stored under :data:`SPEC`; the other arguments are its attributes (``words``: any
    iterable, stored as a tuple). The default is kept in the spec too; :func:`check_settings` checks it
    on each instance.
    """
    spec = SettingSpec(kind, low, high, low_open, tuple(words), optional, unit, why, per_axis, default)
    return dataclasses.field(default=default, metadata={SPEC: spec})


def specs(cls):
    """Dict field name -> :class:`SettingSpec` of the fields of ``cls`` declared with :func:`setting`, in order.

    ``cls``: a dataclass (TypeError otherwise) or one of its instances; other fields are left out.
    """
    return {f.name: f.metadata[SPEC] for f in dataclasses.fields(cls) if SPEC in f.metadata}


def check_settings(config):
    """Check every declared field of ``config`` in place (:meth:`SettingSpec.check`); ValueError for the first invalid.

    Numbers of float fields become Python floats, integral numbers of int fields Python ints, numpy
    booleans Python booleans, and three per-axis numbers a tuple; other fields are left alone. The
    message is ``"<class>.<name> must be <what is valid> (<why>), got <value>"``.
    """
    for name, spec in specs(config).items():
        setattr(config, name, spec.check(f"{type(config).__name__}.{name}", getattr(config, name)))


def parse_setting(cls, pair):
    """``"NAME=VALUE"`` -> ``(name, value)`` for a field of ``cls``, parsed strictly; ValueError otherwise.

    Split at the first ``=``, spaces around the name ignored; the value is parsed by
    :meth:`SettingSpec.parse` (module docstring), then checked like a value given in Python; a declared
    word comes back in lower case, three numbers of a per-axis setting as a tuple. The ValueError names
    a missing ``=``, an unknown name (listing the settings) or a bad value.
    """
    name, sep, text = pair.partition("=")
    name = name.strip()
    declared = specs(cls)
    if not sep or name not in declared:
        what = "expected NAME=VALUE" if not sep else f"unknown setting {name!r}"
        raise ValueError(f"{pair!r}: {what}; settings are {', '.join(declared)}")
    return name, declared[name].parse(name, text)


def parse_settings(cls, pairs):
    """``["sigma_pixel=2", ...]`` -> keyword arguments of ``cls``; ValueError for a refused pair or a name given twice.

    Each pair as :func:`parse_setting`; the dict keeps the order given.
    """
    out = {}
    for pair in pairs:
        name, value = parse_setting(cls, pair)
        if name in out:
            raise ValueError(f"{pair!r}: {name} is set twice")
        out[name] = value
    return out


def format_value(value):
    """``value`` as ``NAME=VALUE`` would set it (for ``--help``): ``true``/``false``, ``none``, short numbers.

    E.g. ``"true"``, ``"none"``, ``"1000000"``, ``"1e-06"``, ``"auto"``, ``"0.1,0.02,0.02"``.
    """
    if isinstance(value, bool) or value is None:
        return str(value).lower()
    if isinstance(value, tuple):
        return ",".join(format_value(v) for v in value)
    return _number(value) if isinstance(value, (int, float)) else str(value)


def _shown(value):
    """A value for a message: numpy scalars and arrays as plain Python numbers."""
    if isinstance(value, np.ndarray):
        return tuple(value.tolist())
    return value.item() if isinstance(value, np.generic) else value


def _range_text(low, high, low_open):
    if low is None and high is None:
        return ""
    if high is None:
        return f" {'>' if low_open else '>='} {_number(low)}"
    if low is None:
        return f" <= {_number(high)}"
    return f" in {'(' if low_open else '['}{_number(low)}, {_number(high)}]"


def _number(x):
    """``1000000`` rather than ``1e+06`` for whole numbers below 1e7."""
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e7 else f"{x:g}"


def _in_range(value, low, high, low_open):
    above = low is None or (value > low if low_open else value >= low)
    return above and (high is None or value <= high)


def _coerce(kind, value):
    """``(ok, value)``: whether ``value`` is of ``kind`` (numpy scalars too), converted to it."""
    if kind is bool:
        return isinstance(value, (bool, np.bool_)), bool(value) if isinstance(value, np.bool_) else value
    if kind is str:
        return isinstance(value, str), value
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        return False, value
    if kind is int:
        integral = float(value).is_integer()  # False for nan and inf
        return integral, int(value) if integral else value
    return True, float(value)


def _from_text(kind, word):
    """Strict conversion of command-line text; ValueError when it is not of ``kind``."""
    lower = word.lower()
    if kind is bool:
        if lower in _TRUE or lower in _FALSE:
            return lower in _TRUE
        raise ValueError(word)
    if kind is int:
        return int(word.replace("_", "x"))  # int() would accept "1_0"
    if kind is float:
        value = float(word.replace("_", "x"))
        if not math.isfinite(value):
            raise ValueError(word)
        return value
    return word
