"""What a user can get wrong or run into, and the exit codes of ``pt-render``.

Every failure a user can cause or meet is one line on stderr (``pt-render: error: ...``)
naming the file, JSON path or flag and what is allowed, and one of these exit codes;
``--debug`` shows the traceback as well. A traceback without ``--debug`` is a bug.
"""
import signal

EXIT_OK = 0
EXIT_INTERNAL = 1      # a bug in pt-render: the one-line message asks for a report
EXIT_INPUT = 2         # bad input: scene, referenced file, flag, or too big for this machine
EXIT_IO = 3            # an output could not be written where asked (saved elsewhere if possible)
# Stopped by a signal (after saving what was done): 128 + the signal's number, as a shell
# reports it: 130 SIGINT (Ctrl-C), 143 SIGTERM, 129 SIGHUP.


class InputError(Exception):
    """Bad input given on the command line (a flag, a reference image), or a render too
    big for this machine. ``str()`` is the one-line message."""


class OutputError(Exception):
    """An output file that cannot be written."""


class DarkImageWarning(UserWarning):
    """A finished render whose image is black, or nearly: no light reached the camera."""


class Interrupted(KeyboardInterrupt):
    """A stop request (SIGINT, SIGTERM, SIGHUP): the render ends after saving."""

    def __init__(self, signum=signal.SIGINT):
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)

    @property
    def exit_code(self):
        return 128 + self.signum
