"""The classifier in a process of its own, behind the same ``classify`` call.

Detection and recognition are both Python code that calls numpy, OpenCV and OpenGL
many times per frame; on two threads of one interpreter they also take turns holding the
GIL. On an NVIDIA H100 host (16 cores, 2026-11-24) the node's recognition thread took
33-43 ms a frame at 1920x1080 where the same classifier alone took 22-29 ms, and the
node did not keep up with 30 Hz. :class:`ClassifierProcess` moves the classifier out of
the interpreter (the pipeline's ``classifier_process`` setting): it starts a worker (a
new interpreter, ``python -m`` this module: no thread, lock or OpenGL context of the
parent is copied, and the parent's main script is not imported again, so it needs no
``if __name__ == '__main__'`` guard), builds the :class:`~.classifier.Classifier`
there, and sends it each frame and its candidates through a socket pair (a 640x480
frame is 300 kB: well under a millisecond). On the 2-core development machine it made no
consistent difference (``bench/bench_stage_contention.py``, bench/RESULTS.md): there the
cores, not the GIL, are what the stages share.

Failure is reported, not hidden:

- the worker cannot build the classifier (a bad bank file, say): the constructor raises
  what the worker raised;
- a frame the classifier refuses: :meth:`ClassifierProcess.classify` raises the same
  error (a :class:`~speed_sign_detector.errors.ClassifierInputError`), and the worker
  goes on;
- the worker dies (killed, out of memory): :meth:`~ClassifierProcess.classify` raises
  :class:`~speed_sign_detector.errors.ClassifierProcessError` with its exit code, and
  the next call starts a new worker, so that a node keeps running;
- the worker hangs (no answer within ``answer_timeout_s``, 30 s by default): it is
  killed, and the same error and restart follow.
"""
from __future__ import annotations

import logging
import multiprocessing.connection
import os
import pickle
import signal
import socket
import subprocess
import sys
from collections.abc import Sequence
from types import TracebackType
from typing import Any, Self

import numpy as np

from speed_sign_detector.blas_threads import BLAS_THREAD_VARIABLES
from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.errors import ClassifierProcessError
from speed_sign_detector.recognition.classification import Classification

__all__ = ['ClassifierProcess', 'start_classifier_processes']

LOGGER = logging.getLogger(__name__)

#: Seconds a closing worker is given to finish before it is terminated.
CLOSE_TIMEOUT_S = 5.0
#: Seconds a new worker may take to build its classifier (filter banks built from
#: scratch take seconds to a minute on 2 cores) before it is taken for hung.
START_TIMEOUT_S = 600.0


def _serve(connection: multiprocessing.connection.Connection) -> None:
    """The worker: receive the :class:`ClassifierConfig`, build the classifier, then
    answer ``(gray, candidates)`` requests until ``None`` arrives or the socket closes.
    Each answer is ``('ok', result)`` or ``('error', exception)``."""
    from speed_sign_detector.recognition.classifier import Classifier
    try:
        classifier = Classifier(connection.recv())
    except Exception as err:  # noqa: BLE001 (every failure goes back to the parent)
        _send_error(connection, err)
        return
    connection.send(('ok', None))
    while True:
        try:
            request = connection.recv()
        except (EOFError, OSError):
            return
        if request is None:
            return
        gray, candidates = request
        try:
            answer = classifier.classify(gray, candidates)
        except Exception as err:  # noqa: BLE001 (the parent raises it)
            _send_error(connection, err)
        else:
            connection.send(('ok', answer))


def _send_error(connection: multiprocessing.connection.Connection, err: Exception) -> None:
    """Send ``err`` itself where it pickles, else its type and message."""
    try:
        pickle.dumps(err)
    except Exception:  # noqa: BLE001 (an exception that does not pickle)
        err = ClassifierProcessError(f'{type(err).__name__}: {err}')
    connection.send(('error', err))


class ClassifierProcess:
    """A :class:`~.classifier.Classifier` running in a worker process.

    Use it as the classifier itself (``classify`` only), from one thread at a time, and
    close it (or use it as a context manager) to stop the worker.

    Args:
        config: the classifier's configuration (the worker builds it).
        answer_timeout_s: a worker that has not answered a frame after this many seconds
            is taken for hung: it is killed and the call raises (> 0).
        wait: wait here until the worker has built its classifier; False returns once it
            is started, and :meth:`wait_until_ready` (or the first ``classify``) waits,
            so that several workers build their classifiers at the same time (see
            :func:`start_classifier_processes`).

    Raises:
        ClassifierError: what building the classifier raised in the worker (for example
            a :class:`~speed_sign_detector.errors.BankFileError`).
        ClassifierProcessError: when the worker cannot be started or exits first.
    """

    def __init__(self, config: ClassifierConfig, answer_timeout_s: float = 30.0, *,
                 wait: bool = True) -> None:
        if not answer_timeout_s > 0:
            raise ValueError(f'answer_timeout_s must be > 0, got {answer_timeout_s}')
        self.config = config
        self.answer_timeout_s = answer_timeout_s
        self._process: subprocess.Popen[bytes] | None = None
        self._connection: multiprocessing.connection.Connection | None = None
        self._ready = False
        self._spawn()
        if wait:
            self.wait_until_ready()

    @property
    def pid(self) -> int | None:
        """The worker's process id; None when none runs."""
        return None if self._process is None else self._process.pid

    def classify(self, gray: np.ndarray, candidates: Sequence[Candidate]
                 ) -> tuple[Classification, ...]:
        """:meth:`.classifier.Classifier.classify`, in the worker.

        Raises:
            ClassifierInputError: for a frame the classifier refuses (the worker goes on).
            ClassifierProcessError: when the worker died, or did not answer within
                ``answer_timeout_s`` (it is killed); the next call starts another.
        """
        if self._connection is None:
            LOGGER.warning('starting a new classifier process (the previous one exited)')
            self._spawn()
        self.wait_until_ready()
        self._send((gray, tuple(candidates)))
        status, answer = self._receive(self.answer_timeout_s, 'while classifying a frame; '
                                       'the next frame starts a new one')
        if status == 'error':
            raise answer
        return answer

    def wait_until_ready(self) -> None:
        """Block until the worker has built its classifier (at once when it has).

        Raises:
            ClassifierError: what building the classifier raised in the worker (the
                worker is stopped).
            ClassifierProcessError: the worker exited, or was not ready within
                ``START_TIMEOUT_S`` (it is killed).
        """
        if self._ready:
            return
        status, answer = self._receive(START_TIMEOUT_S, 'before it was ready')
        if status == 'error':
            self.close()
            raise answer
        self._ready = True

    def close(self) -> None:
        """Stop the worker: ask it to finish, terminate it when it does not in time."""
        if self._connection is not None:
            try:
                self._connection.send(None)
            except (OSError, ValueError):
                pass
        self._reap()

    def _spawn(self) -> None:
        """Start a worker and send it the configuration (it builds the classifier while
        :meth:`wait_until_ready` waits for it)."""
        parent_end, child_end = socket.socketpair()
        try:
            # one BLAS thread unless the environment says otherwise (see blas_threads)
            environment = dict(os.environ)
            for name in BLAS_THREAD_VARIABLES:
                environment.setdefault(name, '1')
            process = subprocess.Popen(
                [sys.executable, '-m', __name__, str(child_end.fileno())],
                pass_fds=(child_end.fileno(),), stdin=subprocess.DEVNULL, env=environment)
        except OSError as err:
            parent_end.close()
            raise ClassifierProcessError(f'cannot start the classifier process: {err}'
                                         ) from err
        finally:
            child_end.close()
        connection = multiprocessing.connection.Connection(parent_end.detach())
        self._process, self._connection, self._ready = process, connection, False
        self._send(self.config)

    def _send(self, message: object) -> None:
        """Send ``message`` to the worker.

        Raises:
            ClassifierProcessError: the worker exited.
        """
        connection = self._connection
        assert connection is not None
        try:
            connection.send(message)
        except OSError as err:
            code = self._reap()
            raise ClassifierProcessError(f'the classifier process exited (exit code {code}) '
                                         'before it took a request') from err

    def _receive(self, timeout_s: float, when: str) -> tuple[str, Any]:
        """The worker's next ``(status, answer)``.

        Raises:
            ClassifierProcessError: the worker exited, or did not answer within
                ``timeout_s`` (it is then killed); ``when`` ends the message.
        """
        connection = self._connection
        if connection is None:
            raise ClassifierProcessError(f'the classifier process had exited {when}')
        try:
            if not connection.poll(timeout_s):
                self._kill()
                raise ClassifierProcessError(f'the classifier process did not answer within '
                                             f'{timeout_s:g} s and was killed, {when}')
            status, answer = connection.recv()
        except (EOFError, OSError) as err:
            code = self._reap()
            raise ClassifierProcessError(f'the classifier process exited (exit code {code}) '
                                         f'{when}') from err
        return status, answer

    def _kill(self) -> None:
        """Kill the worker at once (it may be stopped or hung) and forget it."""
        if self._process is not None:
            self._process.kill()
        self._reap()

    def _reap(self) -> int | None:
        """Forget the worker (waited for; terminated when it does not exit in time) and
        its socket; its exit code."""
        code = None
        process = self._process
        if process is not None:
            try:
                code = process.wait(CLOSE_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                process.terminate()
                try:
                    code = process.wait(CLOSE_TIMEOUT_S)
                except subprocess.TimeoutExpired:
                    process.kill()
                    code = process.wait()
        if self._connection is not None:
            self._connection.close()
        self._process, self._connection, self._ready = None, None, False
        return code

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()


def start_classifier_processes(config: ClassifierConfig, count: int,
                               answer_timeout_s: float = 30.0
                               ) -> tuple[ClassifierProcess, ...]:
    """``count`` :class:`ClassifierProcess` workers that build their classifiers at the
    same time (a start takes about as long as one worker's).

    Raises:
        ValueError: ``count`` below 1.
        ClassifierError, ClassifierProcessError: as :class:`ClassifierProcess`; the
            workers already started are stopped.
    """
    if count < 1:
        raise ValueError(f'count must be >= 1, got {count}')
    processes: list[ClassifierProcess] = []
    try:
        for _ in range(count):
            processes.append(ClassifierProcess(config, answer_timeout_s, wait=False))
        for process in processes:
            process.wait_until_ready()
    except BaseException:
        for process in processes:
            process.close()
        raise
    return tuple(processes)


def main(argv: Sequence[str]) -> int:
    """The worker's entry point: ``python -m speed_sign_detector.recognition.
    classifier_process FD``, FD the socket to the parent."""
    # Ctrl+C in a terminal reaches the whole process group: the parent decides when the
    # worker stops (it closes the socket or sends None), so the worker ignores it
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with multiprocessing.connection.Connection(int(argv[1])) as connection:
        _serve(connection)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
