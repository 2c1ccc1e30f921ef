"""Errors a user can fix.

Every subclass of :class:`NlosfwError` is reported by the command line as a
single line (no traceback) with its ``exit_status``: 2 for input and configuration
mistakes, 1 for a storage failure (a full disk). Anything else is a bug.
:class:`RunInterrupted` is not an error: it is how SIGINT, SIGTERM and SIGHUP stop a run.
"""

from __future__ import annotations

#: Exit status of the command line for errors the user can fix.
USER_ERROR_EXIT_STATUS = 2
#: Exit status of the command line when storage fails (a full disk).
STORAGE_ERROR_EXIT_STATUS = 1


def one_line(err: BaseException, whole: bool = False) -> str:
    """``err``'s message on one line (of its cause when it has none), or its type name.

    The first line only, or with ``whole`` every line joined by spaces. For quoting
    another library's exception inside a one-line nlosfw error.
    """
    while not str(err).strip() and err.__cause__ is not None:
        err = err.__cause__
    lines = [line.strip() for line in str(err).strip().splitlines() if line.strip()]
    if not lines:
        return type(err).__name__
    return " ".join(lines) if whole else lines[0]


class NlosfwError(Exception):
    """Base class of errors caused by input, configuration or environment."""

    #: The command line's exit status for this error.
    exit_status: int = USER_ERROR_EXIT_STATUS


class ConfigError(NlosfwError, ValueError):
    """An option has an unknown name or an invalid value.

    ``option`` is the dotted name of the offending option (``model.lr``) so a
    caller that knows the enclosing config group can prefix it.
    """

    def __init__(self, option: str, problem: str) -> None:
        self.option = option
        self.problem = problem
        super().__init__(f"{option}: {problem}" if option else problem)

    def within(self, prefix: str) -> ConfigError:
        """The same error with ``prefix`` prepended to the option name."""
        option = f"{prefix}.{self.option}" if self.option else prefix
        return ConfigError(option, self.problem)


class DataError(NlosfwError, ValueError):
    """Arrays or files do not hold valid NLOS data (shape, dtype, NaN, fields)."""


class PluginError(NlosfwError):
    """A plugin is unknown, duplicated or cannot be loaded."""


class FitError(NlosfwError):
    """A field model failed to train (diverged, empty data, not fitted)."""


class StorageError(NlosfwError, OSError):
    """A file could not be written: the disk is full, or the directory is not writable.

    Nothing partial is left behind; the message names the path (and, for a full disk,
    the space needed and the space free).
    """

    exit_status = STORAGE_ERROR_EXIT_STATUS


class RunInterrupted(BaseException):
    """SIGINT, SIGTERM or SIGHUP arrived: stop, clean up and exit with 128 + the signal number.

    A :class:`BaseException` (like :class:`KeyboardInterrupt`) so that ``except
    Exception`` in a plugin does not swallow it.
    """

    def __init__(self, signum: int) -> None:
        import signal

        self.signum = int(signum)
        self.signal_name = signal.Signals(self.signum).name
        super().__init__(f"interrupted by {self.signal_name}")

    def __reduce__(self) -> tuple[type[RunInterrupted], tuple[int]]:
        """Pickled by its signal number: a sweep's worker process sends it to its parent."""
        return (RunInterrupted, (self.signum,))

    @property
    def exit_status(self) -> int:
        """128 + the signal number (130 for SIGINT, 143 for SIGTERM, 129 for SIGHUP), as shells
        report."""
        return 128 + self.signum
