"""Print the third-party runtime dependencies of dexroll and its client, one per line.

``make deps`` installs them on their own (a Docker layer that survives source edits);
``make install`` then installs the two packages themselves without dependencies. The
service's own extras are included (:data:`SERVICE_EXTRAS`: ``sim``, so that ``make run``
and the Docker image execute plans in MuJoCo, ``POST /v1/plans/{id}/simulation``).
"""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OWN = {"dexroll", "dexroll-client"}
#: extras of dexroll that the service installs with its runtime dependencies
SERVICE_EXTRAS = ("sim",)


def requirements() -> list[str]:
    out: list[str] = []
    for path in (ROOT / "pyproject.toml", ROOT / "clients" / "python" / "pyproject.toml"):
        project = tomllib.loads(path.read_text())["project"]
        extras = project.get("optional-dependencies", {}) if path.parent == ROOT else {}
        deps = [*project["dependencies"], *[d for e in SERVICE_EXTRAS for d in extras.get(e, [])]]
        for dep in deps:
            name = dep.split(";")[0].split("[")[0]
            for sep in "<>=!~ ":
                name = name.split(sep)[0]
            if name.strip().lower() not in OWN and dep not in out:
                out.append(dep)
    return out


if __name__ == "__main__":
    print("\n".join(requirements()))
