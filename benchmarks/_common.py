"""What the benchmark scripts share: the repository's paths, ``--set`` overrides through the
configuration's own parameter handling, the machine a result was measured on, result files."""
from __future__ import annotations

import json
import os
import platform
import subprocess
from pathlib import Path
from typing import Any, Iterable

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
SIM_CACHE = ROOT / "data" / "sim"
CI_BAG = ROOT / "bags" / "tunnel_entrance_32x256"

SET_HELP = ("pipeline parameter instead of its default, dotted below pipeline (e.g. "
            "lili.return_ratio=0.1); repeatable")


def parse_set(items: Iterable[str], prog: str = "benchmark") -> dict[str, str]:
    """``["KEY=VALUE", ...]`` (``--set`` arguments) as a dict; SystemExit on a malformed item."""
    out: dict[str, str] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise SystemExit(f"{prog}: --set takes KEY=VALUE, got {item!r}")
        out[key.strip()] = value
    return out


def apply_set(config: Any, overrides: dict[str, Any], prog: str = "benchmark") -> Any:
    """``overrides`` (names below ``pipeline.``, values as YAML scalars) applied through
    :func:`lili_odom.config.apply_overrides` (types, names and ranges checked); SystemExit
    with the parameter's message when one is invalid."""
    from lili_odom.config import apply_overrides

    try:
        return apply_overrides(config, overrides)
    except ValueError as exc:
        raise SystemExit(f"{prog}: {exc}") from None


def config_with(overrides: dict[str, Any] | None = None, path: str | Path | None = None,
                prog: str = "benchmark") -> Any:
    """The defaults (or the parameter file ``path``, relative to the repository) with
    ``overrides`` applied (see :func:`apply_set`)."""
    from lili_odom.config import load_config

    if path is not None and not Path(path).is_absolute():
        path = ROOT / path
    return apply_set(load_config(path), dict(overrides or {}), prog)


def git(*args: str) -> str:
    """Output of ``git ARGS`` in the repository ("" when git is unavailable)."""
    try:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True,
                              timeout=20).stdout.rstrip()
    except (OSError, subprocess.SubprocessError):
        return ""


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine_info() -> dict[str, Any]:
    """CPU, cores, Python, the git commit and uncommitted changes under ``lili_odom/``."""
    dirty = [line[3:] for line in git("status", "--porcelain", "--", "lili_odom").splitlines()]
    return {"cpu": cpu_model(), "cores": os.cpu_count(), "python": platform.python_version(),
            "commit": git("rev-parse", "--short", "HEAD").strip(), "uncommitted_lili_odom": dirty}


def write_results(out_dir: Path, name: str, markdown: str | None = None,
                  data: Any = None) -> Path:
    """``out_dir/name.md`` (when given) and ``out_dir/name.json`` (when given); returns the
    Markdown path (or the JSON one)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if data is not None:
        (out_dir / f"{name}.json").write_text(json.dumps(data, indent=1) + "\n")
    if markdown is not None:
        (out_dir / f"{name}.md").write_text(markdown)
        return out_dir / f"{name}.md"
    return out_dir / f"{name}.json"
