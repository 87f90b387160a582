"""One self-contained HTML page for a scene (:mod:`tactrec.viewer.scene`).

The page inlines plotly.js (from the ``plotly`` package, MIT licence; its
licence header is kept) and the scene as JSON: it makes no network request
when opened.  A side panel lists the scene's models with their errors and
probabilities; choosing one shows its surface and the curves as that model's
registration places them.  The page sets ``document.body.dataset.drawn`` once
the first view is drawn, for a headless browser to wait on.
"""

from __future__ import annotations

import html
import json

__all__ = ["page"]

COLOURS = ["#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b"]

_SCRIPT = """
const scene = JSON.parse(document.getElementById('scene').textContent);
const colours = %(colours)s;
function fmt(x) {
  if (x === null || x === undefined) { return '-'; }
  return (x !== 0 && Math.abs(x) < 1e-3) ? Number(x).toExponential(1) : Number(x).toPrecision(3);
}
let light = {x: 1e5, y: 1e5, z: 1e5};
function mesh(part, colour, name, opacity) {
  const v = part.vertices, f = part.triangles;
  return {type: 'mesh3d', name: name, x: v.map(p => p[0]), y: v.map(p => p[1]), z: v.map(p => p[2]),
          i: f.map(t => t[0]), j: f.map(t => t[1]), k: f.map(t => t[2]), color: colour, opacity: opacity,
          flatshading: false, lighting: {ambient: 0.45, diffuse: 0.8, specular: 0.15}, lightposition: light, hoverinfo: 'name',
          showlegend: false};
}
function traces(view) {
  const out = [mesh(view.surface, '#c8c8c8', view.model, 1.0)];
  view.curves.forEach((c, n) => out.push(mesh(c, colours[n %% colours.length], 'curve ' + (n + 1), 1.0)));
  const p = view.contact, d = view.normal;
  out.push({type: 'scatter3d', mode: 'markers', x: [p[0]], y: [p[1]], z: [p[2]], name: 'contact',
            marker: {size: 5, color: '#000000'}, showlegend: false});
  out.push({type: 'scatter3d', mode: 'lines', x: [p[0], p[0] + d[0]], y: [p[1], p[1] + d[1]],
            z: [p[2], p[2] + d[2]], name: 'normal', line: {width: 6, color: '#000000'}, showlegend: false});
  return out;
}
const layout = {margin: {l: 0, r: 0, t: 0, b: 0}, paper_bgcolor: '#ffffff',
                scene: {aspectmode: 'data', xaxis: {title: {text: 'x'}}, yaxis: {title: {text: 'y'}},
                        zaxis: {title: {text: 'z'}}}};
const config = {displaylogo: false, responsive: true, modeBarButtonsToRemove: ['toImage']};
function show(index) {
  const view = scene.views[index];
  document.querySelectorAll('#models li').forEach((li, n) => li.classList.toggle('chosen', n === index));
  const s = view.surface;
  document.getElementById('note').textContent = s.faces < s.original_faces
    ? view.model + ': drawn with ' + s.faces + ' of its ' + s.original_faces + ' triangles (decimated for display)'
    : view.model + ': ' + s.faces + ' triangles';
  // look at the contact's side: the camera along the normal, from the scene's centre
  const d = view.normal, n = Math.hypot(d[0], d[1], d[2]) || 1;
  const eye = {x: 2.4 * d[0] / n, y: 2.4 * d[1] / n, z: 2.4 * d[2] / n};
  const up = Math.abs(d[2] / n) > 0.9 ? {x: 0, y: 1, z: 0} : {x: 0, y: 0, z: 1};
  layout.scene.camera = {eye: eye, up: up};
  light = {x: 1e5 * (eye.x + up.x), y: 1e5 * (eye.y + up.y), z: 1e5 * (eye.z + up.z)};      // from behind the viewer, above
  Plotly.react('plot', traces(view), layout, config).then(() => { document.body.dataset.drawn = 'yes'; });
}
const list = document.getElementById('models');
scene.views.forEach((view, n) => {
  const li = document.createElement('li');
  li.dataset.model = view.model;
  li.textContent = view.model + '  error ' + fmt(view.error) + ' ' + view.units + '  p ' + fmt(view.probability);
  li.addEventListener('click', () => show(n));
  list.appendChild(li);
});
(scene.others || []).forEach((other) => {
  const li = document.createElement('li');
  li.dataset.model = other.model;
  li.className = 'other';
  li.title = other.reason;
  li.textContent = other.model + (other.error === null ? '  no registration' : '  error ' + fmt(other.error));
  list.appendChild(li);
});
if (scene.views.length) { show(0); } else { document.body.dataset.drawn = 'yes'; }
"""

_STYLE = """
body { margin: 0; font: 14px sans-serif; display: flex; height: 100vh; }
#side { width: 340px; flex: none; padding: 12px; overflow-y: auto; border-right: 1px solid #ddd; box-sizing: border-box; }
#plot { flex: 1; }
#models { list-style: none; padding: 0; }
#models li { padding: 5px; cursor: pointer; border-radius: 4px; white-space: pre; overflow: hidden; text-overflow: ellipsis; font-size: 13px; }
#models li.chosen { background: #e8eef8; font-weight: bold; }
#models li.other { color: #999; cursor: default; }
#note { color: #666; font-size: 12px; }
"""


def page(scene: dict) -> str:
    """The HTML text of one self-contained page drawing ``scene``."""
    import plotly.offline

    payload = json.dumps(scene, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    heading = scene.get("title") or "tactrec"
    summary = ""
    if scene.get("best") is not None:
        summary = (f"recognised: <b>{html.escape(str(scene['best']))}</b>, confidence "
                   f"{scene.get('confidence', 0):.3f}, unknown {scene.get('unknown', 0):.3f}")
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        f"<title>{html.escape(heading)}</title><style>{_STYLE}</style>"
        f"<script>{plotly.offline.get_plotlyjs()}</script></head>\n<body>"
        f"<div id=\"side\"><h3>{html.escape(heading)}</h3><p>{summary}</p>"
        "<p>Models (choose one to see its registration; grey: none to show, hover for why):</p><ul id=\"models\"></ul><p id=\"note\"></p></div>"
        "<div id=\"plot\"></div>"
        f"<script type=\"application/json\" id=\"scene\">{payload}</script>"
        f"<script>{_SCRIPT % {'colours': json.dumps(COLOURS)}}</script></body></html>\n"
    )
