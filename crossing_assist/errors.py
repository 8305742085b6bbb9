"""One user-error base class and one command-line wrapper for all six commands (stdlib only).

Every module's "you gave me something I cannot use" exception derives from :class:`UserError`
(itself a ``ValueError``, so older ``except ValueError`` code keeps working). Commands run their
body through :func:`run_cli`, which turns what escapes into an exit status and one line:

========================  ======  ==============================================================
what escaped              status  what is printed on stderr
========================  ======  ==============================================================
nothing                   body's  (the body's own output)
:class:`UserError`        2       ``error: <first line of the message>``
``OSError``               2       ``error: <file>: <reason>`` (no space, permission, bad name...)
``KeyboardInterrupt``     130     ``interrupted`` plus the command's own hint (e.g. how to resume)
``BrokenPipeError``       0       nothing (``crossing-data stats DIR | head``)
anything else             1       ``error: internal error (<Type>: <first line>); rerun with --debug``
========================  ======  ==============================================================

SIGTERM (``kill PID``) is turned into ``SystemExit(143)`` while the body runs, so the clean-up
of temporary files runs as it does for Ctrl-C (only SIGKILL skips it; the next run sweeps those).

``--debug`` anywhere on the command line (or ``CROSSING_DEBUG=1``) re-raises instead, so the
traceback is shown. The flag is taken out of the arguments before the command's parser sees them.
"""

from __future__ import annotations

import os
import signal
import sys
from typing import Callable, Sequence

EXIT_USER = 2
EXIT_INTERNAL = 1
EXIT_INTERRUPTED = 130
DEBUG_FLAG = "--debug"


class UserError(ValueError):
    """Bad input or an impossible request: the message is one line naming the problem and the fix."""


def first_line(exc: BaseException) -> str:
    """The first non-empty line of ``str(exc)``, or the exception's type name."""
    for line in str(exc).splitlines():
        if line.strip():
            return line.strip()
    return type(exc).__name__


def short_repr(value: object, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters, for an error line: a 5000-digit number or a
    pasted list must not flood it, and a string's newlines show escaped."""
    try:
        text = repr(value)
    except ValueError:  # an int too long for str() (over sys.get_int_max_str_digits)
        return f"<{type(value).__name__} too long to show>"
    return text if len(text) <= limit else text[:limit - 3] + "..."


def os_error_line(exc: OSError) -> str:
    """``<file>: <reason>`` for an OSError (the file name shortened when absurdly long)."""
    name = exc.filename if exc.filename is not None else ""
    name = str(name)
    if len(name) > 120:
        name = name[:60] + "..." + name[-40:]
    reason = exc.strerror or first_line(exc)
    return f"{name}: {reason}" if name else reason


def split_debug(argv: Sequence[str] | None) -> tuple[list[str], bool]:
    """(``argv`` without ``--debug``, whether debug output was asked for)."""
    args = list(sys.argv[1:] if argv is None else argv)
    debug = DEBUG_FLAG in args or os.environ.get("CROSSING_DEBUG", "") not in ("", "0")
    return [a for a in args if a != DEBUG_FLAG], debug


def run_cli(body: Callable[[list[str]], int], argv: Sequence[str] | None = None, *,
            interrupted: str | Callable[[], str] = "") -> int:
    """Run ``body(args)`` (``args`` = ``argv`` without ``--debug``) and map what escapes to an
    exit status and one line, per the table in the module docstring. ``interrupted``: the hint
    printed after ``interrupted`` on Ctrl-C (a callable is asked at that moment, so it can check
    whether there is anything to resume)."""
    args, debug = split_debug(argv)
    previous = _on_sigterm()
    try:
        return int(body(args) or 0)
    except SystemExit:
        raise
    except KeyboardInterrupt:
        if debug:
            raise
        hint = interrupted() if callable(interrupted) else interrupted
        print("interrupted" + (f"; {hint}" if hint else ""), file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except OSError:
            pass
        return 0
    except UserError as exc:
        if debug:
            raise
        print(f"error: {first_line(exc)}", file=sys.stderr)
        return EXIT_USER
    except OSError as exc:
        if debug:
            raise
        print(f"error: {os_error_line(exc)}", file=sys.stderr)
        return EXIT_USER
    except RecursionError as exc:
        if debug:
            raise
        print(f"error: input nested too deeply ({first_line(exc)})", file=sys.stderr)
        return EXIT_USER
    except Exception as exc:  # noqa: BLE001 - the one place that turns surprises into one line
        if debug:
            raise
        print(f"error: internal error ({type(exc).__name__}: {first_line(exc)}); rerun with {DEBUG_FLAG} "
              "for the traceback and report it", file=sys.stderr)
        return EXIT_INTERNAL
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _terminate(signum, frame) -> None:  # noqa: ARG001
    raise SystemExit(128 + signal.SIGTERM)


def _on_sigterm():
    """Install :func:`_terminate` for SIGTERM; returns the previous handler (None when not the
    main thread, where handlers cannot be set)."""
    try:
        return signal.signal(signal.SIGTERM, _terminate)
    except ValueError:
        return None
