"""The body of a worker process of :class:`~sb3_es.evaluation.processes.ProcessEvaluator`, and its error transport.

A worker builds its envs (a :class:`~sb3_es.evaluation.worker.ShareRunner`), says it is ready, then serves the
driver's calls over its pipe: run a share (lingering signalled by ``("done", token)`` and ended by a shared
integer), keep a noise table, call a function on its VecEnv. An exception is sent back with its traceback, and
re-raised in the driver with that traceback as its cause: ``SystemExit`` and ``KeyboardInterrupt`` too (a worker
ignores ``SIGINT``, so they come from the env's code), which would otherwise end the worker and pass for a crash.
"""

from __future__ import annotations

import os
import signal
import traceback
import weakref
from multiprocessing.connection import Connection
from typing import Any

import cloudpickle

from sb3_es.evaluation.worker import ShareRunner
from sb3_es.strategies.noise import SharedNoiseTable

#: The driver's ends of every worker pipe of this process: a forked worker closes its copies, so that a worker
#: sees the end of its pipe when the driver goes away.
DRIVER_ENDS: weakref.WeakSet[Connection] = weakref.WeakSet()


class RemoteTraceback(Exception):
    """The traceback of an exception raised in a worker process (set as the ``__cause__`` of the re-raised one)."""

    def __init__(self, tb: str) -> None:
        super().__init__(tb)
        self.tb = tb

    def __str__(self) -> str:
        return f'\n"""\n{self.tb}"""'


def worker_main(conn: Connection, config: bytes, stop: Any, tables: list[SharedNoiseTable]) -> None:
    """Body of a worker process: build the envs, then serve calls until the driver says so or goes away."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the driver stops its workers on Ctrl-C
    driver = os.getppid()
    for end in list(DRIVER_ENDS):  # copies inherited by fork
        end.close()

    def reply(*message: Any) -> None:
        try:
            data = cloudpickle.dumps(message)  # as Ray: lambdas and local classes (in infos, say) cross too
        except Exception as e:  # e.g. an info value that does not pickle (a lock, an open file)
            error = RuntimeError(
                f"The worker's {message[0]!r} reply could not be sent to the driver{_unpicklable_part(message)}: "
                f"{type(e).__name__}: {e}"
            )
            data = cloudpickle.dumps(("error", error, traceback.format_exc()))
        conn.send_bytes(data)

    def serve(runner: ShareRunner, kind: str, args: Any) -> None:
        if kind == "run":
            payload, jobs, seed, token = args
            payload = cloudpickle.loads(payload)
            if token is None:
                reply("result", runner.run(payload, jobs, seed))
                return

            def share_done() -> None:
                reply("done", token)

            def keep_lingering() -> bool:  # until the driver says so, or is gone (the worker is then re-parented)
                return stop.value != token and os.getppid() == driver

            reply("result", runner.run(payload, jobs, seed, share_done, keep_lingering))
        elif kind == "table":
            runner.noise_tables[args.key] = args.noise
        elif kind == "call":
            reply("result", cloudpickle.loads(args)(runner.env))

    try:
        try:
            runner = ShareRunner(cloudpickle.loads(config))
        except BaseException as e:  # e.g. an unknown env id; a factory calling sys.exit()
            reply("error", portable(e), traceback.format_exc())
            return
        for table in tables:
            runner.noise_tables[table.key] = table.noise
        reply("ready", runner.env.num_envs)
        while True:
            try:
                kind, args = conn.recv()
            except (EOFError, OSError):  # the driver is gone
                return
            if kind == "exit":
                return
            try:
                serve(runner, kind, args)
            except BaseException as e:  # SystemExit, KeyboardInterrupt too: raised by the env's code, not a crash
                reply("error", portable(e), traceback.format_exc())
    except (BrokenPipeError, ConnectionResetError):  # the driver is gone
        return


def portable(error: BaseException) -> BaseException:
    """
    :return: ``error`` if the driver can rebuild it from its pickle, else a ``RuntimeError`` with its type and
        message (an exception whose ``__init__`` takes other arguments than its ``args`` cannot be rebuilt).
    """
    try:
        cloudpickle.loads(cloudpickle.dumps(error))
        return error
    except Exception:
        return RuntimeError(f"{type(error).__module__}.{type(error).__qualname__}: {error}")


def _unpicklable_part(message: tuple[Any, ...]) -> str:
    """:return: Where in a reply the value that does not pickle is, as words (empty if not in an info)."""
    output = message[1] if len(message) > 1 else None
    for _, slot, info in output.get("done_infos", []) if isinstance(output, dict) else []:
        for key, value in info.items():
            try:
                cloudpickle.dumps(value)
            except Exception:
                return (
                    f" (the info of env slot {slot} holds {type(value).__name__} under {key!r}, which does not "
                    "pickle: keep info values plain, or leave that key out)"
                )
    return ""


def raise_remote(error: BaseException, tb: str) -> None:
    """Raise an exception from a worker, with the worker's traceback as its cause."""
    raise error from RemoteTraceback(tb)
