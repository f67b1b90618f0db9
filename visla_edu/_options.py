"""The values of the command line's options, parsed (argparse ``type=`` functions).

Each function takes the option's text and returns its value, or raises
:class:`argparse.ArgumentTypeError` with one line that names what is wrong: argparse then
prints ``usage`` and that line, and :mod:`visla_edu.cli` exits with status 2.
"""

import argparse

__all__ = ["settings_help", "frames", "integer_in", "blas_threads", "path", "port", "setting", "smoother_setting",
           "stride"]


def settings_help():
    """The epilog of ``run --help`` (:func:`visla_edu.smoother.settings_help`), imported only when asked."""
    from visla_edu import smoother

    return smoother.settings_help()


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
    from visla_edu.filters import FilterConfig, _settings

    if text.strip().lower().startswith("blas_threads"):
        raise argparse.ArgumentTypeError(f"{text!r}: blas_threads is not a filter setting; use --blas-threads N "
                                         "(or --blas-threads none)")
    try:
        name, value = _settings.parse_setting(FilterConfig, text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    if name == "extrinsic_correction":
        from visla_edu.diagnostics import CORRECTIONS

        if value not in ("auto", *CORRECTIONS):
            raise argparse.ArgumentTypeError(f"extrinsic_correction must be 'auto' or one of {list(CORRECTIONS)}, "
                                             f"got {value!r}")
    return name, value


def smoother_setting(text):
    """``--smoother-set NAME=VALUE``: ``(name, value)`` (:func:`visla_edu.smoother.parse_setting`)."""
    from visla_edu import smoother

    try:
        return smoother.parse_setting(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def stride(text):
    """``--landmark-stride N``: as ``--set landmark_stride=N``."""
    return setting(f"landmark_stride={text}")[1]
