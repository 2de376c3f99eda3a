"""The daemon's sockets: one ZeroMQ context, the CURVE authenticator, the publisher and the
control server, opened together and closed in the one order that cannot hang.

Each socket uses CURVE when it binds TCP (the given --keys, else this user's local keys;
daemon/config.py `socket_keys`); ipc:// alone is guarded by the socket file's mode.
"""

from __future__ import annotations

import os

import zmq
from sasprobe.daemon.config import DaemonConfig, socket_keys
from sasprobe.daemon.control_server import ControlServer
from sasprobe.daemon.publisher import Publisher
from sasprobe.daemon.socket_monitor import raise_fd_limit
from sasprobe.protocol.security import start_authenticator

from sasprobe.common.errors import UserError


class Network:
    def __init__(self, config: DaemonConfig, handler) -> None:
        raise_fd_limit()
        pub_keys = socket_keys(config.pub, config.keys)
        ctl_keys = socket_keys(config.ctl, config.keys)
        self.context = zmq.Context()
        # ZeroMQ's I/O thread works for clients (a 256 MiB upload is copied there). At the
        # loop's real-time priority a large upload stalls the loop (equal priorities do not
        # preempt), and so it does at FIFO priority 1 (real-time throttling stops every
        # real-time thread of a CPU that used its share); at normal priority the loop comes
        # first. Poses then reach subscribers later on a busy machine.
        self.context.set(zmq.THREAD_SCHED_POLICY, os.SCHED_OTHER)
        self.context.set(zmq.THREAD_PRIORITY, 0)
        keys = pub_keys or ctl_keys
        self.auth = start_authenticator(self.context, keys) if keys else None
        self.publisher: Publisher | None = None
        self.control: ControlServer | None = None
        try:
            self.publisher = Publisher(self.context, config.pub, pub_keys)
            self.control = ControlServer(self.context, config.ctl, handler, ctl_keys)
        except zmq.ZMQError as exc:
            self.close()
            where = " / ".join(config.pub + config.ctl)
            if exc.errno == zmq.EADDRINUSE:
                raise UserError(
                    f"cannot bind {where}: another process holds the address; is a daemon "
                    f"already running there? (`sasprobe status --ctl {config.ctl[0]}` asks it; "
                    "--pub and --ctl choose other endpoints)"
                ) from None
            raise UserError(f"cannot bind {where}: {exc}") from None
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Stop the control thread, close the sockets, the authenticator, the context (safe to
        repeat)."""
        if self.control is not None:
            self.control.stop()
        if self.publisher is not None:
            self.publisher.close()
        if self.auth is not None:
            self.auth.stop()
        if self.context is not None:
            self.context.term()
        self.control = self.publisher = self.auth = self.context = None
