"""The ``sbmpc`` command line. Exit codes: 0 success, 1 negative answer, 2 bad input."""
from __future__ import annotations

import argparse
import re
import sys

from ..errors import InputError, NoResult


class _Parser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line and exit code 2, a wrong choice
    in the form of every other message (the flag, what was expected, what was found)."""

    def error(self, message):  # noqa: D401
        m = re.match(r"argument (\S+): invalid choice: (.+?) \(choose from (.+?)\)", message)
        if m:          # (the choices quoted or not, by Python version; a flag's long name)
            choices = ", ".join(repr(c.strip().strip("'")) for c in m.group(3).split(","))
            message = f"{m.group(1).split('/')[-1]}: expected one of {choices}, found {m.group(2)}"
        self.exit(2, f"{self.prog}: error: {message}\n")


class _ReaderMayLeave:
    """stdout for one command: when its reader goes away (``| head``, ``| true``) the
    rest of what it prints is dropped and the command carries on, so it still writes
    its files and returns its own exit code (a failed plan was exit 0 with no JSON)."""

    def __init__(self, stream):
        self._stream, self.gone = stream, False

    def _left(self):
        import os
        self.gone = True
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), self._stream.fileno())
        except (OSError, ValueError, AttributeError):   # a stream without a descriptor (tests)
            pass

    def write(self, text):
        if not self.gone:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._left()
        return len(text)

    def flush(self):
        if not self.gone:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._left()

    def __getattr__(self, name):
        return getattr(self._stream, name)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="sbmpc", description="Motion planning for skid-steered robots with the "
                "closed-loop dynamic model of Yu et al. (2010).",
                epilog="--debug (anywhere on the line): show the traceback of an internal error.")
    from .. import __version__
    p.add_argument("--version", action="version", version=f"sbmpc {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    from . import calibrate, diagnose, importer, plan, protocol, run, schema, shadow, simulate, sweep
    simulate.add_parser(sub)
    plan.add_parsers(sub)
    diagnose.add_parsers(sub)
    calibrate.add_parsers(sub)
    protocol.add_parsers(sub)
    run.add_parsers(sub)
    shadow.add_parsers(sub)
    sweep.add_parsers(sub)
    importer.add_parsers(sub)
    schema.add_parsers(sub)
    return p


def _broken_install(exc: ImportError) -> str:
    """What an import error while building the parser means: most often folders left in
    site-packages by an earlier plain install (numba's cache files, which pip does not
    remove), which Python then takes for the package in place of the installed one."""
    import sbmpc
    if getattr(sbmpc, "__file__", None) is None:          # a namespace package: no __init__ ran
        where = ", ".join(str(p) for p in getattr(sbmpc, "__path__", []))
        return (f"the sbmpc package is shadowed by folders without its code ({where}): left over from an "
                f"earlier install (pip leaves numba's cache files behind); remove them and install again")
    return f"the installation is incomplete: {exc} (install again: pip install -e .)"


SIGNED = ("--start", "--goal", "--radius", "--v", "--v0", "--slope-deg")   # options whose value may be negative


def _negative_values(argv: list) -> list:
    """``--start -1,3`` as ``--start=-1,3``: argparse takes a value that starts with '-'
    and is not a plain number (a list, an exponent) for an option and refuses it."""
    out, i = [], 0
    while i < len(argv):
        a = argv[i]
        if a in SIGNED and i + 1 < len(argv) and re.match(r"-\.?\d", argv[i + 1]):
            out.append(f"{a}={argv[i + 1]}")
            i += 2
        else:
            out.append(a)
            i += 1
    return out


def _one_line(exc) -> str:
    """An error's message on one line: a library's own message may carry line breaks (the
    YAML parser's 'special characters are not allowed' and the place it found one)."""
    return " ".join(str(exc).split())


def main(argv=None) -> int:
    """:func:`_main`, with stderr that may lose its reader too (``2>&1 | true``: the exit
    code of a bad input was 1, Python's for the error line it could not print)."""
    err, sys.stderr = sys.stderr, _ReaderMayLeave(sys.stderr)
    try:
        return _main(argv)
    finally:
        try:
            sys.stderr.flush()
        finally:
            sys.stderr = err


def _main(argv=None) -> int:
    """Run one command. Exit codes: 0 done, 1 no result (no path, a failed run), 2 bad
    input (one line saying which file, key or flag, what was expected and what was
    found), 3 an internal error (one line; ``--debug`` shows the traceback), 130
    interrupted."""
    argv = _negative_values(list(sys.argv[1:] if argv is None else argv))
    debug = "--debug" in argv
    if debug:
        argv.remove("--debug")
    try:
        parser = build_parser()
    except ImportError as exc:
        if debug:
            raise
        print(f"sbmpc: error: {_broken_install(exc)}", file=sys.stderr)
        return 3
    args = parser.parse_args(argv)
    import warnings

    def one_line(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, UserWarning) and not issubclass(category, DeprecationWarning):
            print(f"sbmpc {args.command}: warning: {message}", file=sys.stderr)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")                  # library chatter (numba, matplotlib)
            from maps import MapWarning
            warnings.simplefilter("always", MapWarning)      # the user's own input: one line each
            warnings.showwarning = one_line
            out, sys.stdout = sys.stdout, _ReaderMayLeave(sys.stdout)
            try:
                return int(args.func(args) or 0)
            finally:
                sys.stdout.flush()
                sys.stdout = out
    except InputError as exc:
        print(f"sbmpc {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except NoResult as exc:
        print(f"sbmpc {args.command}: {_one_line(exc)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"sbmpc {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:            # the reader went away (| head): not an error of ours
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:
        if debug:
            raise
        fn = str(exc.filename) if exc.filename else ""
        name = f" '{fn if len(fn) <= 80 else fn[:80] + ' ...'}'" if fn else ""
        print(f"sbmpc {args.command}: error: cannot read or write{name}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except UnicodeDecodeError:
        if debug:
            raise
        print(f"sbmpc {args.command}: error: an input file is not UTF-8 text (binary data where text was expected)",
              file=sys.stderr)
        return 2
    except MemoryError:
        if debug:
            raise
        print(f"sbmpc {args.command}: error: out of memory (an input larger than this machine can hold?)",
              file=sys.stderr)
        return 2
    except Exception as exc:            # the last resort: never a bare traceback
        if debug:
            raise
        msg = str(exc).splitlines()[0][:200] if str(exc) else ""
        print(f"sbmpc {args.command}: internal error: {type(exc).__name__}: {msg} "
              f"(please report it; run again with --debug for the traceback)", file=sys.stderr)
        return 3


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
