"""The daemon's answers to control requests; they run on the control thread.

One method per command of the protocol (protocol/control.py COMMANDS). A request
that changes state does the slow part away from the loop (parsing a structure and
building an engine happen in the daemon's worker process, daemon/structure_worker.py;
settings are checked here) and hands the loop a closure through the daemon's change
queue (daemon/changes.py), so the loop only ever swaps finished objects in.
"""

from __future__ import annotations

import hashlib
import logging
import os
import time
from pathlib import Path

from sasprobe.daemon.access import path_below
from sasprobe.daemon.buttons import KEY_CLUTCH_LEASE_S
from sasprobe.daemon.findings_job import FindingsJob
from sasprobe.daemon.haptics import validate_settings
from sasprobe.daemon.haptics.settings import needs_rebuild, split_changes
from sasprobe.daemon.marks import drop_mark
from sasprobe.devices.workspace.mapping import validate_rotation
from sasprobe.molecule.packed import pack_structure
from sasprobe.protocol.control import COMMANDS, ControlReply, Request
from sasprobe.protocol.scene import merge_lights

from sasprobe import __version__
from sasprobe.common.errors import UserError

log = logging.getLogger("sasprobe")


class RequestHandlers:
    def __init__(self, daemon) -> None:
        self.daemon = daemon
        self._handlers = {
            "ping": self.ping,
            "status": self.status,
            "get_scene": self.get_scene,
            "get_structure": self.get_structure,
            "load": self.load,
            "set": self.set,
            "record_start": self.record_start,
            "record_stop": self.record_stop,
            "shutdown": self.shutdown,
            "view": self.view,
            "clutch": self.clutch,
            "recentre": self.recentre,
            "mark": self.mark,
            "findings": self.findings,
        }
        self.findings_job: FindingsJob | None = None  # the newest `findings` analysis
        # (structure, its arrays packed, their sha256) for get_structure
        self._packed: tuple = (None, b"", "")
        assert set(self._handlers) == set(COMMANDS), "every protocol command needs its handler"

    def handle(self, request: Request) -> ControlReply:
        """The reply to a decoded request (ControlServer turns exceptions into error replies)."""
        result, data = self._handlers[request.cmd](request)
        return ControlReply(ok=True, result=result, data=data)

    # ------------------------------------------------------------------ reading
    def ping(self, request):
        return {"pong": True, "t_ns": time.monotonic_ns(), "daemon_version": __version__}, None

    def status(self, request):
        d = self.daemon
        if request.args.get("reset_stats"):
            d.changes.submit(lambda seq: d.loop.reset_stats())
        summary = d.loop.stats.summary()
        cpu_s = d.loop.cpu_since_reset_ns() / 1e9
        summary["cpu_percent"] = (
            100.0 * cpu_s / summary["window_s"] if summary["window_s"] > 0 else None
        )
        summary["target_rate_hz"] = d.rate_hz
        summary["stalls"] = d.loop.watchdog.as_dict()
        summary["lost_ticks"] = d.loop.timing.lost
        summary["realtime"] = d.realtime
        guard = d.pipeline.guard
        rec = d.recorder
        return {
            "daemon_version": __version__,
            "pid": os.getpid(),
            "uptime_s": (time.monotonic_ns() - d.started_ns) / 1e9,
            "loop": summary,
            "device": {
                **d.device.info.as_dict(),
                "faulted": guard.faulted,
                "faults": guard.faults,
                "fault_ticks": guard.fault_ticks,
                "last_fault": guard.last_reason,
                "clamped_ticks": guard.clamped_ticks,
                "write_failures": d.loop.write_failures,
            },
            "structure": {
                "name": d.structure.name,
                "sha256": d.structure.sha256,
                "n_atoms": d.structure.n_atoms,
            },
            "publisher": {
                "endpoints": d.publisher.endpoints,
                "subscribers": d.publisher.subscribers,
                "poses_sent": d.publisher.poses_sent,
                "scenes_sent": d.publisher.scenes_sent,
                "send_failures": d.publisher.send_failures,
            },
            "control": {
                "endpoints": d.control.endpoints,
                "requests": d.control.requests,
                "errors": d.control.errors,
                "restarts": d.control.restarts,
            },
            "recording": None if rec is None else {**rec.stats().as_dict(), "error": rec.error},
            "findings": None if self.findings_job is None else self.findings_job.as_dict(),
        }, None

    def get_scene(self, request):
        return self.daemon.scene, None

    def get_structure(self, request):
        s = self.daemon.structure
        header = {
            "name": s.name,
            "sha256": s.sha256,
            "n_atoms": s.n_atoms,
            "bytes": len(s.source_bytes),
            "gzip": s.source_bytes[:2] == b"\x1f\x8b",
            "keep_water": self.daemon.structure_keep_water,
        }
        if request.args.get("form", "file") == "file":
            return header, s.source_bytes
        if self._packed[0] is not s:  # packed once per structure, for every renderer that joins
            packed = pack_structure(s)
            self._packed = (s, packed, hashlib.sha256(packed).hexdigest())
        _, packed, digest = self._packed
        return {
            **header,
            "form": "arrays",
            "bytes": len(packed),
            "gzip": False,
            "arrays_sha256": digest,
        }, packed

    # ------------------------------------------------------------------ changing
    def load(self, request):
        from sasprobe.molecule.fetch import pdb_id, resolve
        from sasprobe.molecule.loading import MAX_FILE_BYTES, read_regular_file
        from sasprobe.molecule.structure import structure_name

        d = self.daemon
        keep_water = request.args.get("keep_water", False)
        if request.data is not None:
            name = structure_name(request.args.get("name") or "uploaded")  # the stem, as for a path
            data, source = request.data, f"control:{request.args.get('name') or name}"
        else:
            text = request.args["path"]
            # a PDB id comes through the user's fetch cache; a file only from below --load-dir
            path = (
                Path(resolve(text))
                if pdb_id(text)
                else path_below(d.config.load_dir, text, "--load-dir", "load")
            )
            data, name, source = (
                read_regular_file(path, MAX_FILE_BYTES),
                structure_name(path.name),
                str(path),
            )
        structure, engine = d.structure_worker.build(
            data, name, source, keep_water, d.limits, d.settings
        )
        seq = d.changes.submit(lambda seq: d.swap_structure(structure, keep_water, engine, seq))
        log.warning("loaded %s (%d atoms) at tick %d", structure.source, structure.n_atoms, seq)
        return {
            "structure": {
                "name": structure.name,
                "sha256": structure.sha256,
                "n_atoms": structure.n_atoms,
            },
            "seq": seq,
        }, None

    def set(self, request):
        d = self.daemon
        haptic, scene_only = split_changes(dict(request.args))
        settings = validate_settings({**d.settings, **haptic}, d.limits) if haptic else d.settings
        lights = merge_lights(d.lights, scene_only["lights"]) if "lights" in scene_only else None
        engine = self._engine(settings) if needs_rebuild(haptic) else None
        seq = d.changes.submit(
            lambda seq: d.apply_settings(haptic, scene_only, settings, lights, engine, seq)
        )
        return {"seq": seq, "settings": settings, "revision": d.scene_revision}, None

    def record_start(self, request):
        d = self.daemon
        if d.recorder is not None:
            raise UserError(f"already recording to {d.recorder.path}")
        recorder = d.new_recorder(
            path_below(d.config.record_dir, request.args["path"], "--record-dir", "record_start")
        )
        engine = self._engine(d.settings)  # the replay starts from this
        try:
            seq = d.changes.submit(lambda seq: d.attach_recorder(recorder, seq, engine))
        except UserError:
            recorder.close()
            raise
        return {"path": str(recorder.path), "seq": seq}, None

    def _engine(self, settings: dict):
        """A new engine for the current structure, built in the worker process."""
        d = self.daemon
        s = d.structure
        return d.structure_worker.build(
            s.source_bytes, s.name, s.source, d.structure_keep_water, d.limits, settings
        )[1]

    def record_stop(self, request):
        recorder = self.daemon.changes.submit(self.daemon.detach_recorder)
        if recorder is None:
            raise UserError("not recording")
        return recorder.close().as_dict(), None

    # ------------------------------------------------------------------ the workspace
    def view(self, request):
        """The workspace view turned: the mapping turns with it, about the probe."""
        rotation = validate_rotation(request.args["rotation"])
        d = self.daemon
        seq = d.changes.submit(lambda seq: d.turn_view(rotation, seq))
        return {"seq": seq, "revision": d.scene_revision}, None

    def clutch(self, request):
        """The window's clutch key: held for KEY_CLUTCH_LEASE_S unless renewed, or let go."""
        d = self.daemon
        held = request.args["held"]
        seq = d.changes.submit(lambda seq: (d.inputs.key_clutch(held, time.monotonic_ns()), seq)[1])
        return {"seq": seq, "held": held, "lease_s": KEY_CLUTCH_LEASE_S if held else None}, None

    def recentre(self, request):
        d = self.daemon
        seq = d.changes.submit(lambda seq: (d.workspace_action("recentre", {}, seq), seq)[1])
        return {"seq": seq}, None

    def mark(self, request):
        d = self.daemon
        label = request.args.get("label")
        mark = d.changes.submit(lambda seq: drop_mark(d, seq, label, "control"))
        return {"mark": mark, "seq": mark["seq"]}, None

    def findings(self, request):
        """Start the analysis of the recording so far; `status` says when it is done."""
        recorder = self.daemon.recorder
        if recorder is None:
            raise UserError(
                "findings are read from the session's recording: start one first "
                "(record_start, or sasprobe daemon --record FILE)"
            )
        if self.findings_job is not None and self.findings_job.running:
            raise UserError(
                f"a findings analysis is still running (into {self.findings_job.out_dir})"
            )
        self.findings_job = FindingsJob(
            recorder.path, request.args["dir"], request.args.get("probe_radius_A")
        )
        return self.findings_job.as_dict(), None

    def shutdown(self, request):
        self.daemon.request_stop("shutdown request")
        return {"stopping": True}, None
