"""The package's Fast DDS profile for full-resolution clouds, and loading it by default.

``config/dds/fastdds.xml`` keeps Fast DDS's default transports (shared memory on one machine,
UDPv4 otherwise) with a 32 MB shared-memory segment instead of 512 KB, so a publisher of 6.3 MB
OS1-128 clouds does not drop fragments of best-effort samples (see the file and docs/ros.md).

:func:`apply_dds_defaults` points ``FASTRTPS_DEFAULT_PROFILES_FILE`` at that file for the
current process, before ``rclpy.init``. ``lili_odom_node``, ``lili-odom play`` and the launch
file call it. It changes nothing when the user already chose: a profile file
(``FASTRTPS_DEFAULT_PROFILES_FILE`` or ``FASTDDS_DEFAULT_PROFILES_FILE``), builtin transports
(``FASTDDS_BUILTIN_TRANSPORTS``), another middleware (``RMW_IMPLEMENTATION`` not Fast DDS), or
``LILI_ODOM_DDS_PROFILE=0``. Pure Python, no rclpy.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import MutableMapping

__all__ = ["PROFILE_NAME", "profile_path", "apply_dds_defaults"]

PROFILE_NAME = "fastdds.xml"
_USER_CHOICES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE",
                 "FASTDDS_BUILTIN_TRANSPORTS")


def profile_path() -> Path | None:
    """The installed ``config/dds/fastdds.xml``: the ament share directory (colcon install),
    the source tree (editable install), or ``<prefix>/share/lili_odom`` (pip); None if absent."""
    candidates = []
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

        try:
            candidates.append(Path(get_package_share_directory("lili_odom")))
        except (PackageNotFoundError, OSError):  # not installed / AMENT_PREFIX_PATH unset
            pass
    except ImportError:
        pass
    candidates.append(Path(__file__).resolve().parents[2])
    candidates.append(Path(sys.prefix) / "share" / "lili_odom")
    for base in candidates:
        path = base / "config" / "dds" / PROFILE_NAME
        if path.is_file():
            return path
    return None


def apply_dds_defaults(environ: MutableMapping[str, str] | None = None) -> str | None:
    """Set ``FASTRTPS_DEFAULT_PROFILES_FILE`` to the package profile unless the user chose
    (see the module docstring); returns the path set, or None when nothing was changed.
    Must run before the process's first DDS participant (``rclpy.init``)."""
    env = os.environ if environ is None else environ
    if env.get("LILI_ODOM_DDS_PROFILE", "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    if env.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp") not in ("", "rmw_fastrtps_cpp",
                                                                "rmw_fastrtps_dynamic_cpp"):
        return None
    if any(env.get(name) for name in _USER_CHOICES):
        return None
    path = profile_path()
    if path is None:
        return None
    env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(path)
    return str(path)
