"""Structures and haptic engines for a running daemon are made in a child process, never
under the loop's GIL.

gemmi parses a file in one call that holds the GIL (0.3 s for 6ZU5's 165k atoms), a
hostile file can ask for far more, and building the engine's grid runs numpy calls
that hold it for several ms each on such a structure; in the daemon's own process any
of these would stall the loop. So `load`, a `set` that needs a new grid and
`record_start` hand the work to one long-lived worker (`python -m
sasprobe.daemon.structure_worker`), started on first use, which parses with the loader
every command uses, builds the engine as the daemon would, and sends both back as
pickle-5 out-of-band buffers. The daemon reads those with `os.readv` into uninitialised
numpy buffers of their final size (each read releases the GIL; nothing is zeroed or
copied again), so the control thread never holds the GIL for more than a pipe's worth
of bytes. The worker keeps the structure it parsed last, so rebuilding an engine for
it sends no file again. It limits its own address space, drops any real-time priority
it inherited and runs at a lower one; work that takes longer than PARSE_TIMEOUT_S, or
a worker that dies, is killed and answered with one line, and the next request starts
a fresh worker.

Wire between the two (stdin/stdout pipes, little-endian): request = u32 header length,
JSON header {name, source, keep_water, sha256, size, limits, settings}, `size` bytes
(0 when the worker holds the structure of that sha256 already); reply = b"E" u32
length UTF-8 error line, or b"S" u64 pickle length, u32 buffer count, u64 length per
buffer, the pickle of (structure, engine), then the buffers.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import pickle
import select
import struct
import subprocess
import sys
import threading
import time

import numpy as np

from sasprobe.common.errors import UserError

PARSE_TIMEOUT_S = 120.0
WORKER_ADDRESS_SPACE = 8 << 30  # the worker's RLIMIT_AS: a parse that needs more fails in one line
WORKER_NICE = 10
_CHUNK = 1 << 20  # bytes per write to the pipe


class StructureWorker:
    """The daemon's side: one worker process, one request at a time (callers are serialised)."""

    def __init__(self, timeout_s: float = PARSE_TIMEOUT_S) -> None:
        self.timeout_s = timeout_s
        self._proc: subprocess.Popen | None = None
        self._lock = threading.Lock()
        self._held: str | None = None  # sha256 (+ keep_water) of the structure the worker holds
        self.started = 0  # workers started (a restart after a failure counts)

    def build(self, data, name: str, source: str, keep_water: bool, limits, settings: dict):
        """(Structure of these bytes, HapticEngine for it): the structure's source_bytes is
        `data` itself; StructureError / UserError (one line) when the file or the build fails."""
        from sasprobe.molecule.structure import StructureError

        sha256 = hashlib.sha256(data).hexdigest()  # hashlib releases the GIL
        key = f"{sha256}:{bool(keep_water)}"
        with self._lock:
            proc = self._running()
            deadline = time.monotonic() + self.timeout_s
            header = {
                "name": name,
                "source": source,
                "keep_water": bool(keep_water),
                "key": key,
                "limits": dataclasses.asdict(limits),
                "settings": settings,
            }
            try:
                self._send(proc, header, b"" if self._held == key else data, deadline)
                self._held = None  # until the reply says the worker has it
                kind = self._read(proc, 1, deadline)
                if kind == b"E":
                    (n,) = struct.unpack("<I", self._read(proc, 4, deadline))
                    raise StructureError(self._read(proc, n, deadline).decode("utf-8", "replace"))
                if kind != b"S":
                    raise _WorkerFailed("the structure worker sent garbage")
                structure, engine = self._read_pickle(proc, deadline)
                self._held = key
            except _WorkerFailed as exc:
                self._kill()
                raise UserError(f"{source}: {exc}") from None
        structure.source_bytes = data
        return structure, engine

    def close(self) -> None:
        with self._lock:
            self._kill()

    # ------------------------------------------------------------------ plumbing
    def _running(self) -> subprocess.Popen:
        if self._proc is None or self._proc.poll() is not None:
            env = dict(
                os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", PYTHONUNBUFFERED="1"
            )
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "sasprobe.daemon.structure_worker"],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                env=env,
                start_new_session=True,
                bufsize=0,
            )
            self.started += 1
        return self._proc

    def _kill(self) -> None:
        proc, self._proc, self._held = self._proc, None, None
        if proc is not None and proc.poll() is None:
            proc.kill()
        if proc is not None:
            proc.wait()
            for stream in (proc.stdin, proc.stdout):
                stream.close()

    def _send(self, proc, header: dict, data, deadline: float) -> None:
        view = memoryview(data).cast("B")
        header = json.dumps({**header, "size": view.nbytes}).encode()
        fd = proc.stdin.fileno()
        try:
            os.write(fd, struct.pack("<I", len(header)) + header)
            for start in range(0, view.nbytes, _CHUNK):
                _wait(fd, deadline, write=True)
                piece = view[start : start + _CHUNK]
                while piece.nbytes:
                    piece = piece[os.write(fd, piece) :]
        except OSError:
            raise _WorkerFailed("the structure worker ended while reading the file") from None

    def _read(self, proc, n: int, deadline: float) -> bytes:
        buf = np.empty(n, dtype=np.uint8)  # not zeroed: a bytearray(n) memsets under the GIL
        self._read_into(proc, memoryview(buf), deadline)
        return buf.tobytes() if n <= 1 << 16 else buf

    def _read_into(self, proc, view: memoryview, deadline: float) -> None:
        fd = proc.stdout.fileno()
        while view.nbytes:
            _wait(fd, deadline, write=False)
            got = os.readv(fd, [view])
            if got == 0:
                raise _WorkerFailed("the structure worker ended without an answer (out of memory?)")
            view = view[got:]

    def _read_pickle(self, proc, deadline: float):
        pickle_len, count = struct.unpack("<QI", self._read(proc, 12, deadline))
        sizes = struct.unpack(f"<{count}Q", self._read(proc, 8 * count, deadline)) if count else ()
        payload = self._read(proc, pickle_len, deadline)
        buffers = []
        for size in sizes:
            buf = np.empty(size, dtype=np.uint8)
            self._read_into(proc, memoryview(buf), deadline)
            buffers.append(buf)
        return pickle.loads(payload, buffers=buffers)


class _WorkerFailed(Exception):
    pass


def _wait(fd: int, deadline: float, write: bool) -> None:
    remaining = deadline - time.monotonic()
    ready = (
        select.select([], [fd], [], max(remaining, 0))[1]
        if write
        else select.select([fd], [], [], max(remaining, 0))[0]
    )
    if not ready:
        raise _WorkerFailed(f"parsing and building took longer than {PARSE_TIMEOUT_S:g} s; gave up")


# ---------------------------------------------------------------------- the worker process
def _settle() -> None:
    """Normal scheduling at a lower priority, a bounded address space."""
    import resource

    try:
        if os.sched_getscheduler(0) != os.SCHED_OTHER:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        os.nice(WORKER_NICE)
    except (OSError, AttributeError):
        pass
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    limit = (
        WORKER_ADDRESS_SPACE if hard == resource.RLIM_INFINITY else min(WORKER_ADDRESS_SPACE, hard)
    )
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))


def _read_exact(stream, n: int) -> bytes | None:
    data = stream.read(n)
    return data if data is not None and len(data) == n else None


def _serve(stdin, stdout) -> None:
    from sasprobe.daemon.haptics import build_engine
    from sasprobe.devices.base import DeviceLimits
    from sasprobe.molecule import parse_structure

    held_key, held = None, None  # the structure parsed last
    while True:
        raw = _read_exact(stdin, 4)
        if raw is None:
            return  # the daemon closed the pipe: done
        header = json.loads(_read_exact(stdin, struct.unpack("<I", raw)[0]))
        data = _read_exact(stdin, header["size"])
        if data is None:
            return
        try:
            if header["size"] or header["key"] != held_key:
                held_key, held = None, None
                held = parse_structure(
                    data,
                    name=header["name"],
                    source=header["source"],
                    keep_water=header["keep_water"],
                )
                held.source_bytes = b""  # the daemon has the bytes already
                held_key = header["key"]
            limits = header["limits"]
            limits = DeviceLimits(
                **{
                    **limits,
                    "workspace_min_mm": tuple(limits["workspace_min_mm"]),
                    "workspace_max_mm": tuple(limits["workspace_max_mm"]),
                }
            )
            engine = build_engine(held, limits, header["settings"])
        except (UserError, ValueError) as exc:
            _reply_error(stdout, str(exc))
            continue
        except MemoryError:
            _reply_error(
                stdout,
                f"{header['source']}: parsing needs more than the "
                f"{WORKER_ADDRESS_SPACE >> 30} GiB a structure may take",
            )
            continue
        except Exception as exc:  # a bug in a parser: the daemon still answers in one line
            _reply_error(stdout, f"{header['source']}: cannot parse ({type(exc).__name__}: {exc})")
            continue
        buffers: list[pickle.PickleBuffer] = []
        payload = pickle.dumps((held, engine), protocol=5, buffer_callback=buffers.append)
        views = [b.raw() for b in buffers]
        stdout.write(
            b"S"
            + struct.pack("<QI", len(payload), len(views))
            + struct.pack(f"<{len(views)}Q", *(v.nbytes for v in views))
            + payload
        )
        for view in views:
            stdout.write(view)
        stdout.flush()


def _reply_error(stdout, line: str) -> None:
    data = line.splitlines()[0].encode() if line else b"error"
    stdout.write(b"E" + struct.pack("<I", len(data)) + data)
    stdout.flush()


if __name__ == "__main__":
    _settle()
    _serve(sys.stdin.buffer, sys.stdout.buffer)
