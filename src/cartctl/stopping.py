"""Stop signals: SIGINT, SIGTERM and SIGHUP end a command through its shutdown path, like Ctrl-C
(docs/architecture.md). :func:`install` makes the first raise :class:`Interrupted` in the main
thread; later ones, and any inside :func:`deferred`, are only noted. Inside :func:`held` (a
loop's tick: its rows, sinks and timing stay whole) the first is held and raised as the block
ends. Before that (:func:`install_at_start`) one ends the process with one line; hence only
``signal``, ``sys``, ``os`` and ``_thread`` are imported here.
"""

import _thread
import os
import signal
import sys

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
STARTING_LINE = "cartctl: stopped while starting; nothing was done"
"""What a stop signal before the command line took over prints (stderr)."""

_STARTING, _RUNNING, _ENDING = "starting", "running", "ending"
_phase = _RUNNING
_first: int | None = None
_deferred = 0
_holding = 0
_held = False
_hook_replaced = sys.unraisablehook
_redelivered: object = None  # a lock, released once the latest signal is sent again
_order: tuple[int, int] | None = None  # a pipe the signals' numbers go to as they come
_fd_replaced = -1
_main_ident: int | None = None  # the thread install() routed the signals in: the main one


class Interrupted(KeyboardInterrupt):
    """A stop signal arrived; a :class:`KeyboardInterrupt`, so what handles Ctrl-C handles it."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def exit_code(self) -> int:
        return 128 + self.signum


def _handler(signum: int, frame: object) -> None:
    global _first, _held
    if _phase == _STARTING:  # nothing done yet: one line, the signal's exit code, no unwinding
        try:
            sys.stderr.write(STARTING_LINE + "\n")
            sys.stderr.flush()
        finally:
            os._exit(128 + signum)
    if _first is not None or _deferred or _phase == _ENDING:  # a shutdown is under way
        if _first is None:
            _first = came_first(signum)
        return
    _first = signum = came_first(signum)
    if _holding:  # mid-tick: raised as the tick ends (held)
        _held = True
        return
    raise Interrupted(signum)


def came_first(signum: int) -> int:
    """The stop signal that came first of those whose handlers Python runs now, for a handler
    called with ``signum``: Python runs them by number (SIGINT's before that of a SIGTERM that came
    earlier, when both came while the main thread was in a long call or waited for the
    interpreter); after :func:`install` their numbers reach a pipe in the order they came."""
    if _order is None:
        return signum
    try:
        came = os.read(_order[0], 512)
    except OSError:  # nothing there (EAGAIN)
        return signum
    return next((s for s in came if s in STOP_SIGNALS), signum)


def _unraisable(unraisable: object) -> None:
    """The stop signal raised where Python cannot raise it (in a weakref callback, a ``__del__``, a
    generator closed as it is freed: it prints 'Exception ignored in …' and goes on) is sent again,
    from a thread, to be raised in the code around; lost, it would also have made every later
    signal look like a shutdown under way. Anything else goes to the hook this one replaced."""
    global _first, _redelivered
    exc = getattr(unraisable, "exc_value", None)
    if not isinstance(exc, Interrupted) or exc.signum != _first or _phase != _RUNNING:
        _hook_replaced(unraisable)  # type: ignore[arg-type]
        return
    # _thread, not threading: Thread.start() waits, and the handler would raise in here
    _first = None
    _redelivered = _thread.allocate_lock()
    _redelivered.acquire()
    _thread.start_new_thread(_send_again, (exc.signum, _redelivered))


def _send_again(signum: int, done: object) -> None:
    signal.raise_signal(signum)
    done.release()  # type: ignore[attr-defined]


def _route(handler: object) -> dict[int, object]:
    """Set ``handler`` for every stop signal; the handlers replaced ({} outside the main thread)."""
    previous: dict[int, object] = {}
    try:
        for signum in STOP_SIGNALS:
            previous[signum] = signal.signal(signum, handler)  # type: ignore[arg-type]
    except ValueError:  # not the main thread: signals are the main thread's business
        restore(previous)
        return {}
    return previous


def install_at_start() -> None:
    """From now until :func:`install`, a stop signal prints :data:`STARTING_LINE` and exits."""
    global _phase
    _phase = _STARTING
    _route(_handler)


def install() -> dict[int, object]:
    """Route the stop signals to :class:`Interrupted`; returns the handlers replaced."""
    global _first, _deferred, _phase, _held, _hook_replaced, _main_ident
    _first, _deferred, _held = None, 0, False
    previous = _route(_handler)
    if previous:
        _main_ident = _thread.get_ident()
    if previous and sys.unraisablehook is not _unraisable:
        _hook_replaced, sys.unraisablehook = sys.unraisablehook, _unraisable
    if previous and _order is None:
        _watch_order()
    _phase = _RUNNING
    return previous


def _watch_order() -> None:
    """Have each signal's number written to a pipe as it comes (``signal.set_wakeup_fd``)."""
    global _order, _fd_replaced
    pipe = os.pipe()
    for fd in pipe:
        os.set_blocking(fd, False)
    _fd_replaced = signal.set_wakeup_fd(pipe[1], warn_on_full_buffer=False)
    _order = pipe


def _unwatch_order(wakeup_fd: int) -> None:
    """Close the order pipe and put ``wakeup_fd`` back as the wakeup fd (:func:`restore`; -1 in a
    forked child, ``tune --jobs``' workers, which must neither read the parent's order nor feed
    it)."""
    global _order
    if _order is None:
        return
    fds, _order = _order, None
    try:  # noqa: SIM105 - no contextlib here: this module loads before anything else
        signal.set_wakeup_fd(wakeup_fd)
    except ValueError:  # forked from another thread than the main one: no wakeup fd to drop
        pass
    for fd in fds:
        os.close(fd)


os.register_at_fork(after_in_child=lambda: _unwatch_order(-1))


def restore(previous: dict[int, object]) -> None:
    """Put back the handlers :func:`install` replaced; a signal from now on is only noted."""
    global _phase
    _phase = _ENDING
    for signum, handler in previous.items():
        signal.signal(signum, handler)  # type: ignore[arg-type]
    if previous and sys.unraisablehook is _unraisable:
        sys.unraisablehook = _hook_replaced
    if previous:
        _unwatch_order(_fd_replaced)


def ignore() -> None:
    """Ignore the stop signals, for the program's exit (a handler would be reset to the default
    while the interpreter finalises)."""
    _route(signal.SIG_IGN)


def received() -> int | None:
    """The first stop signal received since :func:`install`, or None."""
    return _first


def exit_code(default: int = 130) -> int:
    """128 + the first stop signal's number, or ``default`` when none came (a plain Ctrl-C)."""
    return default if _first is None else 128 + _first


class deferred:  # noqa: N801 - used as a function: ``with stopping.deferred():``
    """Within the block, stop signals are noted (:func:`received`) but raise nothing."""

    def __enter__(self) -> None:
        global _deferred
        _deferred += 1

    def __exit__(self, *exc: object) -> None:
        global _deferred
        _deferred -= 1


class held:  # noqa: N801 - used as a function: ``with stopping.held():``
    """Within the block the first stop signal is held: it raises :class:`Interrupted` as the block
    ends (unless another exception is on its way out), so what the block does is done whole. In
    a thread other than the main one (where Python runs the handlers) it does nothing: held
    there, the signal would be raised in that thread and never in the main one."""

    def __enter__(self) -> None:
        global _holding
        self._here = _thread.get_ident() == _main_ident
        _holding += self._here

    def __exit__(self, kind: object, *exc: object) -> None:
        global _holding, _held
        if not self._here:
            return
        _holding -= 1
        if _held and not _holding:
            _held = False
            if kind is None and _first is not None:
                raise Interrupted(_first)
