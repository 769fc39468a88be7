"""A computation run in a thread while a trial is rolled out (:meth:`corl.learner.CORL._speculate`)."""

from __future__ import annotations

import threading


class _Speculation:
    """``fn(*args, **kwargs)`` in a thread: :meth:`result` joins it and returns its value or raises its error."""

    def __init__(self, fn, args, kwargs) -> None:
        self._value, self._error = None, None
        self._thread = threading.Thread(target=self._run, args=(fn, args, kwargs), name="corl-speculation",
                                        daemon=True)
        self._thread.start()

    def _run(self, fn, args, kwargs) -> None:
        try:
            self._value = fn(*args, **kwargs)
        except BaseException as exc:  # re-raised by result(), where the sequential code makes the call
            self._error = exc

    def join(self) -> None:
        self._thread.join()

    def result(self):
        self.join()
        if self._error is not None:
            raise self._error
        return self._value
