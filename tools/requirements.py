"""Print the third-party runtime dependencies of dexroll and its client, one per line.

``make deps`` installs them on their own (a Docker layer that survives source edits);
``make install`` then installs the two packages themselves without dependencies.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OWN = {"dexroll", "dexroll-client"}


def requirements() -> list[str]:
    out: list[str] = []
    for path in (ROOT / "pyproject.toml", ROOT / "clients" / "python" / "pyproject.toml"):
        for dep in tomllib.loads(path.read_text())["project"]["dependencies"]:
            name = dep.split(";")[0].split("[")[0]
            for sep in "<>=!~ ":
                name = name.split(sep)[0]
            if name.strip().lower() not in OWN and dep not in out:
                out.append(dep)
    return out


if __name__ == "__main__":
    print("\n".join(requirements()))
