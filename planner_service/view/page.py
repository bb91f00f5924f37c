"""The viewer's page: one self-contained HTML file (the scene as JSON, three.js and the
viewer's script inlined), the same whether the service serves it or ``dexroll view``
writes it. Nothing is fetched: it works offline, from a file or an e-mail.

The page carries its own Content-Security-Policy (a ``<meta>`` element; the service sends
it as a header too): nothing may be fetched or run but its own inline scripts and style,
named by their SHA-256 hashes (:func:`content_security_policy`)."""

from __future__ import annotations

import base64
import hashlib
import html
import json
import re
from functools import cache
from importlib import resources
from typing import Any

__all__ = ["THREE_VERSION", "content_security_policy", "page_html"]

#: The three.js release bundled in ``static/three.min.js`` (``js/package.json``).
THREE_VERSION = "0.187.0"


@cache
def _static(name: str) -> str:
    return resources.files(__package__).joinpath("static", name).read_text(encoding="utf-8")


def _json_safe(text: str) -> str:
    """JSON that cannot close the <script> element it is inlined in, nor open one (every
    ``<`` escaped: the same JSON)."""
    return text.replace("<", "\\u003c")


def _script_safe(text: str) -> str:
    """A script that cannot close the <script> element it is inlined in."""
    return re.sub(r"</(script)", lambda m: "<\\/" + m.group(1), text, flags=re.IGNORECASE)


#: The page's icon, inlined (else the browser asks the service for /favicon.ico).
_ICON = ("data:image/svg+xml,%3Csvg xmlns='http://www.w3.org/2000/svg' viewBox='0 0 16 16'%3E"
         "%3Ccircle cx='8' cy='8' r='7' fill='%233b5bdb'/%3E%3C/svg%3E")

_CSS = """
html, body { margin: 0; height: 100%; font: 13px/1.4 system-ui, sans-serif; color: #1d232f; }
body { display: flex; flex-direction: column; }
#view { flex: 1; min-height: 0; position: relative; }
#view canvas { display: block; }
#hud { position: absolute; top: 8px; left: 10px; background: rgba(255,255,255,.85);
       padding: 6px 10px; border-radius: 4px; max-width: 46em; pointer-events: none; }
#hud h1 { font-size: 15px; margin: 0 0 2px; }
#hud .dim { color: #5c6370; }
#legend span { display: inline-block; margin-right: 10px; }
#legend i { display: inline-block; width: 10px; height: 10px; border-radius: 5px;
            margin-right: 4px; vertical-align: -1px; }
#message { position: absolute; top: 45%; width: 100%; text-align: center; color: #b00020; }
#bar { display: flex; gap: 10px; align-items: center; padding: 6px 10px;
       border-top: 1px solid #d6d9df; background: #fff; }
#slider { flex: 1; }
#clock { font-variant-numeric: tabular-nums; min-width: 13em; }
#grasp { font-variant-numeric: tabular-nums; }
#schedule { display: block; width: 100%; cursor: pointer; background: #fff; }
#schedule[hidden] { display: none; }
"""


#: A colour the page's style may name (the scene's palette: #rgb or #rrggbb).
_COLOR = re.compile(r"#[0-9a-fA-F]{3}(?:[0-9a-fA-F]{3})?")
#: The page's inline scripts that run (not its JSON data) and its style element.
_SCRIPT = re.compile(r"<script>(.*?)</script>", re.DOTALL)
_STYLE = re.compile(r"<style>(.*?)</style>", re.DOTALL)


def _sha256(text: str) -> str:
    return "'sha256-" + base64.b64encode(hashlib.sha256(text.encode()).digest()).decode() + "'"


def content_security_policy(page: str, header: bool = False) -> str:
    """The policy of a viewer page: nothing by default; its inline scripts and its style
    element by their hashes; its icon (a ``data:`` image); no base URL, no form target.
    ``header``: as the service sends it (with ``frame-ancestors``, which a ``<meta>``
    cannot carry)."""
    scripts = " ".join(_sha256(m) for m in _SCRIPT.findall(page))
    styles = " ".join(_sha256(m) for m in _STYLE.findall(page))
    policy = (f"default-src 'none'; script-src {scripts}; style-src {styles}; "
              "img-src data:; base-uri 'none'; form-action 'none'")
    return policy + "; frame-ancestors 'none'" if header else policy


def page_html(scene: dict[str, Any]) -> str:
    """The page of a scene (:func:`~.scene.build_scene`), with its policy."""
    page = _page(scene)
    meta = (f'<meta http-equiv="Content-Security-Policy" '
            f'content="{html.escape(content_security_policy(page))}">\n')
    return page.replace("<title>", meta + "<title>", 1)


def _page(scene: dict[str, Any]) -> str:
    title = scene.get("title") or f"{scene['planner']} plan"
    legend = "".join(f'<span><i class="contact-{i}"></i>{html.escape(c["name"])}'
                     f' contact</span>' for i, c in enumerate(scene["contacts"]))
    # the contacts' colours as rules of the style element (an attribute's style would
    # need the policy's 'unsafe-hashes')
    colors = "".join(f"#legend i.contact-{i} {{ background: {c['color']}; }}\n"
                     for i, c in enumerate(scene["contacts"])
                     if _COLOR.fullmatch(str(c["color"])))
    notes = "; ".join(scene.get("notes", []))
    grid = f"; palm grid {scene['palm']['grid'] * 1e3:g} mm" if scene.get("palm") else ""
    data = _json_safe(json.dumps(scene, separators=(",", ":"), allow_nan=False))
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="dexroll viewer (three.js {THREE_VERSION})">
<title>{html.escape(title)} - dexroll</title>
<link rel="icon" href="{_ICON}">
<style>{_CSS}{colors}</style>
</head>
<body>
<div id="view">
 <div id="hud">
  <h1>{html.escape(title)}</h1>
  <div class="dim">{html.escape(scene['planner'])} planner, status
   <b>{html.escape(scene['status'])}</b>: {html.escape(scene['message'])}</div>
  <div id="legend">{legend}<span class="dim">object axes: x red, y green, z blue{grid}</span></div>
  <div class="dim">{html.escape(notes)}</div>
  <div id="grasp"></div>
  <div id="lifted"></div>
  <div id="phase"></div>
 </div>
 <div id="message" hidden></div>
</div>
<div id="bar">
 <button id="play" type="button">&#9654; play</button>
 <input id="slider" type="range" aria-label="time">
 <span id="clock"></span>
 <select id="speed" aria-label="speed">
  <option value="0.25">0.25&times;</option><option value="0.5">0.5&times;</option>
  <option value="1" selected>1&times;</option><option value="2">2&times;</option>
 </select>
 <label><input id="show-links" type="checkbox" checked> links</label>
 <label><input id="show-traces" type="checkbox" checked> traces</label>
 <label><input id="show-cones" type="checkbox" checked> friction cones</label>
 <label><input id="show-axes" type="checkbox" checked> axes</label>
</div>
<canvas id="schedule" aria-label="contact schedule" hidden></canvas>
<script id="dexroll-scene" type="application/json">{data}</script>
<script>/* three.js {THREE_VERSION}, MIT licence (three.LICENSE beside this viewer) */
{_script_safe(_static("three.min.js"))}</script>
<script>{_script_safe(_static("viewer.js"))}</script>
</body>
</html>
"""
