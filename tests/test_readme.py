"""The READMEs' Python examples run as written (the service ones against a live server).

A newcomer pastes these; if an API changes under them, this fails.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import Server

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", ROOT / "clients" / "python" / "README.md"]
DEFAULT_URL = "http://127.0.0.1:8000"


def python_blocks(path: Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", path.read_text(), flags=re.S)


BLOCKS = [(doc, i, code) for doc in DOCS for i, code in enumerate(python_blocks(doc))]


def test_the_readmes_have_python_examples() -> None:
    assert len(python_blocks(DOCS[0])) >= 2  # the client and the library
    assert python_blocks(DOCS[1])


@pytest.mark.parametrize(("doc", "index", "code"), BLOCKS,
                         ids=[f"{d.parent.name}-{i}" for d, i, _ in BLOCKS])
def test_readme_example_runs(doc: Path, index: int, code: str, live_server: Server,
                             tmp_path: Path) -> None:
    # a reader runs a README's examples in order: later ones may use earlier names
    earlier = [c for d, i, c in BLOCKS if d == doc and i < index]
    script = tmp_path / "example.py"
    script.write_text("\n".join([*earlier, code]).replace(DEFAULT_URL, live_server.url))
    proc = subprocess.run([sys.executable, str(script)], cwd=ROOT, capture_output=True,
                          text=True, timeout=600, check=False)
    assert proc.returncode == 0, f"{doc.name} example {index}:\n{proc.stdout}\n{proc.stderr}"


def test_readme_request_example_is_a_valid_request() -> None:
    """The JSON requests shown in the README validate against the wire models."""
    from pydantic import TypeAdapter

    from dexroll_client.models import PlanRequest

    blocks = re.findall(r"```json\n(.*?)```", DOCS[0].read_text(), flags=re.S)
    assert blocks
    adapter: TypeAdapter[PlanRequest] = TypeAdapter(PlanRequest)
    for block in blocks:
        adapter.validate_python(json.loads(block))
