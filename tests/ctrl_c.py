"""Children that take Ctrl-C: a test that sends SIGINT to a command it started.

A process that ignores SIGINT (started so by nohup or a CI runner, or a pytest worker in which
something that ran before left it so) passes that on to its children, and Python then installs no
KeyboardInterrupt handler in them: the command would go on after the test's SIGINT.
``preexec_fn=with_ctrl_c`` gives the child the default disposition, so that it takes Ctrl-C as one
started from a terminal does.
"""
import signal


def with_ctrl_c():
    """A child that takes Ctrl-C as a terminal's does, even when this process was started ignoring it."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
