"""A description of the machine a benchmark ran on, for reports."""

from __future__ import annotations

import os
import platform
import shutil
import subprocess

import numpy as np


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _memory_gib() -> float | None:
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemTotal"):
                    return round(int(line.split()[1]) / 1024**2, 1)
    except OSError:
        pass
    return None


def _os() -> str:
    """The kernel and, where /etc/os-release names it, the distribution."""
    kernel = f"{platform.system()} {platform.release()}"
    try:
        return f"{platform.freedesktop_os_release()['PRETTY_NAME']}, {kernel}"
    except (OSError, KeyError):
        return kernel


def _gpu() -> str | None:
    if not shutil.which("nvidia-smi"):
        return None
    try:
        out = subprocess.run(
            ["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    return out.stdout.strip() or None


def cpu_steal_ticks() -> tuple[int, int] | None:
    """(steal, all) CPU time of the machine so far, in the kernel's clock ticks (/proc/stat);
    None where the kernel does not tell it. Steal is time a hypervisor gave this virtual
    machine's CPUs to others: a real-time loop loses deadlines to it that no scheduling
    policy inside the machine can win back."""
    try:
        with open("/proc/stat") as fh:
            # user nice system idle iowait irq softirq steal
            fields = [int(v) for v in fh.readline().split()[1:9]]
    except (OSError, ValueError):
        return None
    return (fields[7], sum(fields)) if len(fields) == 8 else None


def steal_between(before: tuple[int, int] | None, after: tuple[int, int] | None) -> dict | None:
    """What the hypervisor took between two cpu_steal_ticks(): CPU-seconds and % of the CPU time."""
    if before is None or after is None or after[1] <= before[1]:
        return None
    stolen = after[0] - before[0]
    return {
        "seconds": stolen / os.sysconf("SC_CLK_TCK"),
        "percent": 100.0 * stolen / (after[1] - before[1]),
    }


def gl_renderer() -> str | None:
    """The OpenGL renderer string of a headless EGL context, or None without one."""
    try:
        import moderngl

        ctx = moderngl.create_standalone_context(backend="egl")
    except Exception:  # no EGL or no driver: reported as absent, not an error
        return None
    try:
        return f"{ctx.info['GL_RENDERER']} / OpenGL {ctx.info['GL_VERSION']}"
    finally:
        ctx.release()


def describe(with_gl: bool = False) -> dict:
    info = {
        "cpu": _cpu_model(),
        "cores": os.cpu_count(),
        "memory_gib": _memory_gib(),
        "os": _os(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "gpu": _gpu(),
    }
    if with_gl:
        info["gl_renderer"] = gl_renderer()
    return info


def markdown(info: dict) -> str:
    rows = [f"| {k} | {v if v is not None else 'none'} |" for k, v in info.items()]
    return "| machine | |\n|---|---|\n" + "\n".join(rows)
