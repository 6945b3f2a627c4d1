"""Memory of this process and of the machine, on every platform Blender runs on (a leaf:
imports nothing of Lanterna).

What it computes
    ``peak_memory()`` -> ``PeakMemory(megabytes, source, reason)``: the process's peak
    resident set [MiB = 2^20 bytes], or ``megabytes = None`` with the reason where the
    platform cannot tell. Never raises.
    ``available_memory()`` -> bytes a new allocation can have, or None where unknown (the
    estimate then refuses nothing): ``MemAvailable`` of ``/proc/meminfo`` (Linux),
    ``GlobalMemoryStatusEx``'s ``ullAvailPhys`` (Windows), else free physical pages by
    ``os.sysconf`` where it has them (``psutil`` is not a dependency).

Where the figure comes from, by platform
    ==========  ====================================================  ===================
    platform    call                                                  unit of the call
    ==========  ====================================================  ===================
    Linux, BSD  ``resource.getrusage(RUSAGE_SELF).ru_maxrss``          KiB
    macOS       ``resource.getrusage(RUSAGE_SELF).ru_maxrss``          bytes (getrusage(2)
                                                                      on Darwin)
    Windows     ``K32GetProcessMemoryInfo`` (kernel32, via ctypes):    bytes
                ``PeakWorkingSetSize``
    ==========  ====================================================  ===================

``resource`` exists only on POSIX systems, so it is imported inside the function: a module
that imports this one still imports on Windows.
"""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass

MIB = 1024.0 * 1024.0


@dataclass(frozen=True)
class PeakMemory:
    megabytes: float | None          # peak resident set [MiB]; None: unknown
    source: str                      # what measured it ("" when unknown)
    reason: str = ""                 # why it is unknown

    def to_report(self) -> dict:
        """The report's fields: ``peak_memory_mb`` (rounded to 0.1 MiB, or None) and, where
        it is None, ``peak_memory_note`` with the reason."""
        if self.megabytes is None:
            return {"peak_memory_mb": None, "peak_memory_note": self.reason}
        return {"peak_memory_mb": round(self.megabytes, 1)}


def maxrss_bytes(value: float, platform: str) -> float:
    """``ru_maxrss`` in bytes: Darwin reports bytes, Linux and the BSDs KiB."""
    return float(value) if platform == "darwin" else float(value) * 1024.0


def windows_peak_bytes() -> float:
    """PeakWorkingSetSize of this process [bytes] (raises OSError where the call fails)."""
    import ctypes
    from ctypes import wintypes

    class Counters(ctypes.Structure):                 # PROCESS_MEMORY_COUNTERS
        _fields_ = [("cb", wintypes.DWORD), ("PageFaultCount", wintypes.DWORD),
                    ("PeakWorkingSetSize", ctypes.c_size_t), ("WorkingSetSize", ctypes.c_size_t),
                    ("QuotaPeakPagedPoolUsage", ctypes.c_size_t),
                    ("QuotaPagedPoolUsage", ctypes.c_size_t),
                    ("QuotaPeakNonPagedPoolUsage", ctypes.c_size_t),
                    ("QuotaNonPagedPoolUsage", ctypes.c_size_t),
                    ("PagefileUsage", ctypes.c_size_t), ("PeakPagefileUsage", ctypes.c_size_t)]

    kernel32 = ctypes.WinDLL("kernel32", use_last_error=True)
    counters = Counters()
    counters.cb = ctypes.sizeof(Counters)
    process = kernel32.GetCurrentProcess()
    if not kernel32.K32GetProcessMemoryInfo(process, ctypes.byref(counters), counters.cb):
        raise OSError(ctypes.get_last_error(), "K32GetProcessMemoryInfo failed")
    return float(counters.PeakWorkingSetSize)


def peak_memory(platform: str | None = None) -> PeakMemory:
    """The process's peak resident set (module docstring); ``platform`` defaults to
    ``sys.platform`` (tests pass another to check each branch's units)."""
    platform = sys.platform if platform is None else platform
    try:
        if platform == "win32":
            return PeakMemory(windows_peak_bytes() / MIB, "K32GetProcessMemoryInfo")
        import resource
        usage = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return PeakMemory(maxrss_bytes(usage, platform) / MIB, "getrusage")
    except ImportError as exc:
        return PeakMemory(None, "", f"no way to measure peak memory on {platform}: {exc}")
    except (OSError, AttributeError, ValueError) as exc:
        return PeakMemory(None, "", f"peak memory unavailable on {platform}: {exc}")


def windows_available_bytes() -> int:
    """Available physical memory [bytes] by ``GlobalMemoryStatusEx`` (raises OSError where
    the call fails)."""
    import ctypes
    from ctypes import wintypes

    class Status(ctypes.Structure):                   # MEMORYSTATUSEX
        _fields_ = [("dwLength", wintypes.DWORD), ("dwMemoryLoad", wintypes.DWORD),
                    ("ullTotalPhys", ctypes.c_uint64), ("ullAvailPhys", ctypes.c_uint64),
                    ("ullTotalPageFile", ctypes.c_uint64), ("ullAvailPageFile", ctypes.c_uint64),
                    ("ullTotalVirtual", ctypes.c_uint64), ("ullAvailVirtual", ctypes.c_uint64),
                    ("ullAvailExtendedVirtual", ctypes.c_uint64)]

    status = Status()
    status.dwLength = ctypes.sizeof(Status)
    kernel32 = ctypes.WinDLL("kernel32", use_last_error=True)
    if not kernel32.GlobalMemoryStatusEx(ctypes.byref(status)):
        raise OSError(ctypes.get_last_error(), "GlobalMemoryStatusEx failed")
    return int(status.ullAvailPhys)


def available_memory(platform: str | None = None) -> int | None:
    """Bytes of memory available to a new allocation (module docstring); None when unknown."""
    platform = sys.platform if platform is None else platform
    if platform == "win32":
        try:
            return windows_available_bytes()
        except (OSError, AttributeError, ValueError):
            return None
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None
