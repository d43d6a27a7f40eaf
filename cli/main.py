"""Entry point of the ``posegraph`` command: parse the arguments (``parser``), run the command,
and turn every error into one line and an exit code.

Exit codes: 0 success; 1 ran but did not converge (or Ctrl-C stopped it after the best values
so far were written); 2 bad input or usage; 3 internal error; 130 Ctrl-C with nothing written.
Bad input is reported as one line naming ``file:line``; ``--debug`` shows the traceback instead.
This module imports the library only once Ctrl-C is handled, so that it gives one line at any
point.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import traceback
import warnings

from .errors import EXIT_BAD_INPUT, EXIT_NOT_CONVERGED, UsageError, report

EXIT_INTERNAL = 3
EXIT_INTERRUPTED = 130
"""128 + SIGINT, as a shell reports a command that Ctrl-C stopped."""


def main(argv: list[str] | None = None) -> int:
    arguments = sys.argv[1:] if argv is None else argv
    try:
        return _run(arguments)
    except KeyboardInterrupt as interrupt:  # outside the iterations, which stop cleanly
        written = getattr(interrupt, "paths", None)  # ``io.atomic.InterruptedAfterWriting``
        if written:
            message = f"interrupted (Ctrl-C): wrote {', '.join(written)}; the rest was not written"
        else:
            message = "interrupted (Ctrl-C); nothing written"
        exit_code = EXIT_NOT_CONVERGED if written else EXIT_INTERRUPTED
        report(message)
        if "--json" in arguments:
            command = next((a for a in arguments if not a.startswith("-")), "")
            error = {"kind": "interrupted", "exit_code": exit_code, "message": message}
            document = {"command": command, "error": {**error, "path": None, "line": None}}
            print(json.dumps(document, indent=2))
        return exit_code


def _run(argv: list[str] | None) -> int:
    interrupts = _interrupts()
    from . import commands, data
    from .certify import certify
    from .parser import parser
    from .scale_drift import scale_drift

    if interrupts:  # raised during the imports, and lost there
        raise KeyboardInterrupt

    args = parser().parse_args(argv)
    handlers = {
        "scale-drift": scale_drift,
        "certify": certify,
        "generate": data.generate,
        "datasets": data.datasets,
    }
    handler = handlers.get(args.command) or getattr(commands, args.command)
    return _handle(args, handler)


def _interrupts() -> list[int]:
    """The Ctrl-Cs from now on, each also raised as KeyboardInterrupt as Python's own handler
    raises it: a KeyboardInterrupt raised inside the libraries' imports can be cleared by
    their C code (scipy.sparse importing numpy.f2py), and the command would run on."""
    seen = []

    def interrupted(signum, frame) -> None:
        seen.append(signum)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, interrupted)
    return seen


def _handle(args: argparse.Namespace, handler) -> int:
    """Run ``handler(args)``; every error becomes one line and an exit code."""
    import posegraph

    try:
        with warnings.catch_warnings():
            if not args.debug:  # numpy's overflow warnings name library lines, not the input's
                warnings.simplefilter("ignore", RuntimeWarning)
            return handler(args)
    except BrokenPipeError:  # the reader of stdout went away (`posegraph info g.g2o | head`)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no error at exit
        return EXIT_NOT_CONVERGED
    except (posegraph.GraphFileError, UsageError, ValueError, OSError) as error:
        if args.debug:
            traceback.print_exc()
        message = str(error) if not isinstance(error, OSError) else _os_message(error)
        return _stop(args, EXIT_BAD_INPUT, message, error)
    except Exception as error:  # noqa: BLE001 - the one place that turns crashes into a line
        if args.debug:
            traceback.print_exc()
        first_line = (str(error).splitlines() or [""])[0][:300]
        message = f"internal error: {type(error).__name__}: {first_line} (rerun with --debug)"
        return _stop(args, EXIT_INTERNAL, message, error)


def _stop(args: argparse.Namespace, exit_code: int, message: str, error: Exception) -> int:
    """Report why the command stopped as one line on stderr (unless ``--debug`` printed the
    traceback of an internal error) and, with ``--json``, as the document ``schema.ERROR`` on
    stdout, so that a script reading stdout is told too. Returns ``exit_code``."""
    from posegraph.io import GraphFileError

    if exit_code == EXIT_BAD_INPUT or not args.debug:
        report(message)
    if args.json:
        path, line = None, None
        if isinstance(error, GraphFileError):
            path, line = error.path, error.line
        elif isinstance(error, UsageError):
            path = error.path
        elif isinstance(error, OSError):
            path = error.filename
        document = {
            "kind": "bad_input" if exit_code == EXIT_BAD_INPUT else "internal",
            "exit_code": exit_code,
            "message": message,
            "path": None if path is None else str(path),
            "line": line,
        }
        print(json.dumps({"command": args.command, "error": document}, indent=2))
    return exit_code


def _os_message(error: OSError) -> str:
    where = f"{error.filename}: " if error.filename else ""
    return f"{where}{error.strerror or error}"


if __name__ == "__main__":
    sys.exit(main())
