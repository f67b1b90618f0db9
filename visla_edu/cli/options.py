"""The values of the command line's options, parsed (argparse ``type=`` functions).

Each takes the option's text and returns its value, or raises :class:`argparse.ArgumentTypeError` with one line
that names what is wrong: a usage error of :mod:`visla_edu.cli` (see there).
"""

import argparse
import textwrap

__all__ = ["settings_help", "frames", "integer_in", "blas_threads", "path", "port", "setting", "smoother_setting",
           "stride"]


def settings_help():
    """The epilog of ``run --help``: every ``--set`` and ``--smoother-set`` setting, its default and what it accepts.

    One line a setting (:meth:`visla_edu.settings.SettingSpec.describe`), for
    :class:`argparse.RawDescriptionHelpFormatter`; the configs are imported only when the help is asked for.
    """
    from visla_edu import smoother
    from visla_edu.filters import FilterConfig
    from visla_edu.settings import specs

    own = {name: spec for name, spec in specs(smoother.SmootherConfig).items() if name in smoother.OWN_SETTINGS}
    modes = {**dict.fromkeys(smoother.BATCH_ONLY, "smooth"), **dict.fromkeys(smoother.WINDOW_ONLY, "window")}
    window_reads = f"{', '.join(smoother.FILTER_SETTINGS)} and extrinsic_correction"
    return "\n".join([
        "--set NAME=VALUE, the filter's settings (FilterConfig), their defaults and what they accept:",
        *_setting_lines(specs(FilterConfig), {}),
        "--smoother-set NAME=VALUE (--mode smooth or window; noise and lag come from --set), the smoother's own:",
        *_setting_lines(own, modes),
        *textwrap.wrap(f"--mode window takes from --set only {window_reads}.", 100, subsequent_indent="  ")])


def _setting_lines(specs, modes):
    """``"  name=default  what it accepts"`` per setting of ``specs`` (name -> SettingSpec), aligned.

    ``modes`` maps a name to the one mode that reads it, said after what it accepts.
    """
    from visla_edu.settings import format_value

    heads = {name: f"{name}={format_value(spec.default)}" for name, spec in specs.items()}
    width = max(map(len, heads.values()))
    return [f"  {heads[name]:<{width}}  {spec.describe()}" + (f" ({modes[name]} only)" if name in modes else "")
            for name, spec in specs.items()]


def frames(text):
    """``--frames START:STOP``: ``(start, stop)``, ``start`` 0 and ``stop`` None when left out."""
    parts = text.split(":")
    expected = f"START:STOP frame indices such as 0:300, 500: or :300, got {text!r}"
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"expected {expected}")
    start = integer_in(parts[0], 0, 10**9, expected) if parts[0].strip() else 0
    stop = integer_in(parts[1], 0, 10**9, expected) if parts[1].strip() else None
    return start, stop


def integer_in(text, low, high, expected):
    """``int(text)`` if it lies in ``[low, high]``, else argparse's error naming ``expected``."""
    try:
        n = int(text)
    except ValueError:
        n = low - 1
    if not low <= n <= high:
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
    return n


def blas_threads(text):
    """``--blas-threads`` value: a positive integer or ``none``."""
    if text.strip().lower() == "none":
        return None
    return integer_in(text, 1, 4096, "a positive integer or 'none'")


def path(text):
    """A file or folder option's value: any non-empty path (an empty one is usually an unset variable)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"empty path {text!r} (an unset shell variable?); give a file or folder "
                                         "name, or leave the option out")
    return text


def port(text):
    """``--port`` value: a TCP port, 1 to 65535."""
    return integer_in(text, 1, 65535, "a TCP port number from 1 to 65535")


def setting(text):
    """``--set NAME=VALUE``: ``(name, value)`` parsed strictly by the setting's declaration."""
    from visla_edu.filters import FilterConfig

    if text.strip().lower().startswith("blas_threads"):
        raise argparse.ArgumentTypeError(f"{text!r}: blas_threads is not a filter setting; use --blas-threads N "
                                         "(or --blas-threads none)")
    return _parsed(FilterConfig, text)


def smoother_setting(text):
    """``--smoother-set NAME=VALUE``: ``(name, value)`` of a smoother setting of its own, parsed by its declaration.

    One it takes from the filter's (:data:`visla_edu.smoother.FROM_FILTER`) is refused with the ``--set`` giving it.
    """
    from visla_edu import smoother

    name, sep, _ = (part.strip() for part in text.partition("="))
    if not sep or name not in smoother.OWN_SETTINGS:
        source = smoother.FROM_FILTER.get(name)
        what = ("expected NAME=VALUE" if not sep else f"{name!r} is not a smoother setting" if source is None else
                f"{name} is not a smoother setting of its own (it comes from the filter's settings: use --set "
                f"{source}=VALUE)")
        own = ", ".join(smoother.OWN_SETTINGS)
        raise argparse.ArgumentTypeError(f"{text!r}: {what}; the smoother's settings are {own}")
    return _parsed(smoother.SmootherConfig, text)


def _parsed(config_class, text):
    """:func:`visla_edu.settings.parse_setting` of ``text`` for ``config_class``, its error as argparse's."""
    from visla_edu import settings

    try:
        return settings.parse_setting(config_class, text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def stride(text):
    """``--landmark-stride N``: as ``--set landmark_stride=N``."""
    return setting(f"landmark_stride={text}")[1]
