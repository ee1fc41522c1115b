"""The README's set-up commands, read the way ``.ci/run`` reads them."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
README = REPO_ROOT / "README.md"


def readme_commands() -> list[str]:
    """Return the non-blank lines of the README's first ```sh block (its set-up commands)."""
    text = README.read_text(encoding="utf-8")
    match = re.search(r"^```sh[ \t]*\n(.*?)^```", text, flags=re.MULTILINE | re.DOTALL)
    assert match, "README.md has no ```sh block"
    return [line for line in match.group(1).splitlines() if line.strip()]


def repo_files() -> list[Path]:
    """Files of the working tree that git tracks or would track (not ignored), relative to the root.

    Without git (an unpacked archive) every file except the usual build and run outputs.
    """
    try:
        out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                             cwd=REPO_ROOT, capture_output=True, check=True, timeout=60).stdout
        names = [n for n in out.decode().split("\0") if n]
        return [Path(n) for n in names if (REPO_ROOT / n).is_file()]
    except (OSError, subprocess.CalledProcessError):
        skip = {".git", ".venv", "runs", "build", "dist", "__pycache__", ".pytest_cache", ".benchmarks"}
        return [p.relative_to(REPO_ROOT) for p in REPO_ROOT.rglob("*")
                if p.is_file() and not skip.intersection(p.relative_to(REPO_ROOT).parts)
                and not any(part.endswith(".egg-info") for part in p.parts)]
