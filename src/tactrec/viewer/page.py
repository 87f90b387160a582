"""One self-contained HTML page for a scene (:mod:`tactrec.viewer.scene`, :mod:`tactrec.viewer.session`).

The page inlines plotly.js (from the ``plotly`` package, MIT licence; its
licence header is kept) and the scene as JSON: it makes no network request
when opened.  A side panel lists the scene's models with their errors and
probabilities; choosing one shows its surface and the curves as that model's
registration places them; below, a session's touches and proposed touch with
their colours.  Each view's axes are equal, over the view's ``range``; the camera
looks at the touch from no farther than the surface leaves clear.  Opened with
``#still`` the page draws the first view alone, a touch's curves red and its
contact a white dot (the paper's Fig. 14), for :mod:`tactrec.viewer.still`.  The
page sets ``document.body.dataset.drawn`` once the first view is drawn, for a
headless browser to wait on.
"""

from __future__ import annotations

import html
import json

__all__ = ["page"]

_SCRIPT = """
const scene = JSON.parse(document.getElementById('scene').textContent);
const still = location.hash === '#still';      // a still (tactrec show --png): the plot alone, Fig. 14's colours
if (still) { document.body.classList.add('still'); }
function fmt(x) {
  if (x === null || x === undefined) { return '-'; }
  return (x !== 0 && Math.abs(x) < 1e-3) ? Number(x).toExponential(1) : Number(x).toPrecision(3);
}
let light = {x: 1e5, y: 1e5, z: 1e5};
function mesh(part, colour, name, opacity) {
  const v = part.vertices, f = part.triangles;
  return {type: 'mesh3d', name: name, x: v.map(p => p[0]), y: v.map(p => p[1]), z: v.map(p => p[2]),
          i: f.map(t => t[0]), j: f.map(t => t[1]), k: f.map(t => t[2]), color: colour, opacity: opacity,
          flatshading: false, lighting: {ambient: 0.6, diffuse: 0.65, specular: 0.1}, lightposition: light, hoverinfo: 'name',
          showlegend: false};
}
function line(points, name, colour, width, dash) {
  return {type: 'scatter3d', mode: 'lines', name: name, x: points.map(p => p[0]), y: points.map(p => p[1]),
          z: points.map(p => p[2]), line: {width: width, color: colour, dash: dash || 'solid'}, hoverinfo: 'name',
          showlegend: false};
}
function traces(view) {
  const out = [mesh(view.surface, '#c8c8c8', view.model, 1.0)];
  // Fig. 14: a touch's registered curves in red; a session's touches keep their colours
  const red = still && scene.kind === 'touch';
  view.curves.forEach((c) => out.push(mesh(c, red ? '#d62728' : c.colour, c.name, c.opacity)));
  (view.lines || []).forEach((l) => out.push(line(l.points, l.name, l.colour, 7, l.dash)));
  (view.marks || []).forEach((m) => out.push({type: 'scatter3d', mode: 'markers', name: m.name, x: [m.point[0]],
      y: [m.point[1]], z: [m.point[2]], marker: {size: 5, color: m.colour, symbol: m.symbol}, hoverinfo: 'name',
      showlegend: false}));
  const p = view.contact, d = view.normal;
  out.push({type: 'scatter3d', mode: 'markers', x: [p[0]], y: [p[1]], z: [p[2]], name: 'contact',
            marker: {size: still ? 9 : 5, color: still ? '#ffffff' : '#000000', line: {color: '#000000', width: 2}},
            showlegend: false});
  out.push(line([p, [p[0] + d[0], p[1] + d[1], p[2] + d[2]]], 'normal', '#000000', 6));
  return out;
}
function axis(name) {
  return {title: {text: name}, showbackground: !still, gridcolor: '#e4e4e4', zerolinecolor: '#bbbbbb'};
}
const layout = {margin: {l: 0, r: 0, t: 0, b: 0}, paper_bgcolor: '#ffffff',
                scene: {xaxis: axis('x'), yaxis: axis('y'), zaxis: axis('z')}};
const config = {displaylogo: false, responsive: true, modeBarButtonsToRemove: ['toImage']};
function show(index) {
  const view = scene.views[index];
  document.querySelectorAll('#models li').forEach((li, n) => li.classList.toggle('chosen', n === index));
  const s = view.surface;
  document.getElementById('note').textContent = s.faces < s.original_faces
    ? view.model + ': drawn with ' + s.faces + ' of its ' + s.original_faces + ' triangles (decimated for display)'
    : view.model + ': ' + s.faces + ' triangles';
  // equal axes over the view's range (the surface and the curves that fit it)
  const lo = view.range[0], hi = view.range[1], ext = [0, 1, 2].map(k => hi[k] - lo[k]), big = Math.max(...ext);
  ['xaxis', 'yaxis', 'zaxis'].forEach((a, k) => { layout.scene[a].range = [lo[k], hi[k]]; });
  layout.scene.aspectmode = 'manual';
  layout.scene.aspectratio = {x: ext[0] / big, y: ext[1] / big, z: ext[2] / big};
  // the camera looks at the touch along its normal (a session: from its touches' side), no farther
  // than the surface leaves clear; plotly's camera is in units of the box's largest side
  const d = view.look, t = view.target, up = Math.abs(d[2]) > 0.9 ? {x: 0, y: 1, z: 0} : {x: 0, y: 0, z: 1};
  const centre = [0, 1, 2].map(k => (t[k] - 0.5 * (lo[k] + hi[k])) / big);
  const far = Math.min(still ? 1.6 : 2.0, 0.9 * view.clear * view.size / big);
  const eye = {x: centre[0] + far * d[0], y: centre[1] + far * d[1], z: centre[2] + far * d[2]};
  layout.scene.camera = {eye: eye, up: up, center: {x: centre[0], y: centre[1], z: centre[2]}};
  light = {x: 1e5 * (d[0] + up.x), y: 1e5 * (d[1] + up.y), z: 1e5 * (d[2] + up.z)};      // from behind the viewer, above
  if (still) {
    layout.margin.t = 40;
    layout.title = {text: view.model + ': error ' + fmt(view.error) + ' ' + view.units + ', probability '
                    + fmt(view.probability), x: 0.5, font: {size: 20}};
  }
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
const legend = document.getElementById('legend');
(scene.legend || []).forEach((entry) => {
  const li = document.createElement('li');
  const swatch = document.createElement('span');
  swatch.className = 'swatch';
  swatch.style.background = entry.colour;
  if (entry.faded) { swatch.style.opacity = 0.35; }
  li.appendChild(swatch);
  li.appendChild(document.createTextNode(entry.name));
  legend.appendChild(li);
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
#legend { list-style: none; padding: 0; font-size: 13px; }
.swatch { display: inline-block; width: 12px; height: 12px; margin-right: 6px; border-radius: 2px; }
body.still #side { display: none; }
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
        "<p>Models (choose one to see its registration; grey: none to show, hover for why):</p><ul id=\"models\"></ul>"
        "<ul id=\"legend\"></ul><p id=\"note\"></p></div>"
        "<div id=\"plot\"></div>"
        f"<script type=\"application/json\" id=\"scene\">{payload}</script>"
        f"<script>{_SCRIPT}</script></body></html>\n"
    )
