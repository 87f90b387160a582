"""One self-contained HTML page for a scene (:mod:`tactrec.viewer.scene`, :mod:`tactrec.viewer.session`).

The page inlines three.js and its OrbitControls (``vendor/``: ``build/three.min.js`` and
``examples/js/controls/OrbitControls.js`` of the npm package ``three`` 0.147.0, MIT licence, whose
text the page carries) and the scene as JSON: it makes no network request when opened.  A side
panel lists the scene's models with their errors and probabilities; choosing one shows its surface
and the curves as that model's registration places them; below, a session's touches and proposed
touch with their colours.  The view is drawn in true proportions (equal axes), over a grid of round
squares (the note says their side); the camera looks at the touch along its normal (a session:
from its touches' side) from no farther than the surface leaves clear, and can be turned (drag),
zoomed (wheel) and moved (right drag).  Opened with ``#still`` the page draws the first view alone
with its caption, a touch's curves red and its contact a white dot (the paper's Fig. 14), for
:mod:`tactrec.viewer.still`.  The page sets ``document.body.dataset.drawn`` once the first view is
drawn, for a headless browser to wait on (and ``drawnMs``, the time since its navigation began).
"""

from __future__ import annotations

import hashlib
import html
import json
from importlib import resources

__all__ = ["page", "VENDOR", "library"]

#: the inlined files and their SHA-256, as published in the npm package ``three`` 0.147.0
VENDOR = {
    "three.min.js": "f34446bf875b5fb0dcd93819ffe1d9e182d46634ee855f5d904c6c4ac7cdbc95",
    "OrbitControls.js": "b4c6e53f98538535b11fd6655627d47fb5877b3ad972568bff0a7026c4b6d5c4",
    "three-LICENSE": "fbf3943930dacbf56aabb8dc5d816440bd16aa6f4cc78ddbdf12106ee1807832",
}

_SCRIPT = """
const scene = JSON.parse(document.getElementById('scene').textContent);
const still = location.hash === '#still';      // a still (tactrec show --png): the plot alone, Fig. 14's colours
if (still) { document.body.classList.add('still'); }
function fmt(x) {
  if (x === null || x === undefined) { return '-'; }
  return (x !== 0 && Math.abs(x) < 1e-3) ? Number(x).toExponential(1) : Number(x).toPrecision(3);
}
const plot = document.getElementById('plot');
const renderer = new THREE.WebGLRenderer({antialias: true, preserveDrawingBuffer: true});
renderer.setPixelRatio(window.devicePixelRatio);
renderer.setClearColor(0xffffff, 1);
plot.appendChild(renderer.domElement);
const world = new THREE.Scene();
const camera = new THREE.PerspectiveCamera(30, 1, 0.01, 1000);
const headlight = new THREE.DirectionalLight(0xffffff, 0.65);     // from behind the viewer, above
headlight.position.set(0.3, 0.6, 1.0);
camera.add(headlight);
world.add(camera);
world.add(new THREE.AmbientLight(0xffffff, 0.4));
const controls = new THREE.OrbitControls(camera, renderer.domElement);
controls.addEventListener('change', render);
let shown = null;
function render() { renderer.render(world, camera); }
function resize() {
  const w = plot.clientWidth, h = plot.clientHeight;
  renderer.setSize(w, h);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
  render();
}
window.addEventListener('resize', resize);
function geometry(part) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.Float32BufferAttribute(part.vertices.flat(), 3));
  g.setIndex(part.triangles.flat());
  g.computeVertexNormals();
  return g;
}
function solid(g, colour, opacity) {
  const o = opacity === undefined ? 1 : opacity;
  return new THREE.Mesh(g, new THREE.MeshPhongMaterial({color: colour, shininess: 15, side: THREE.DoubleSide,
                                                         transparent: o < 1, opacity: o}));
}
function dot(point, radius, colour, symbol) {
  if (symbol === 'x') {           // a cross: three crossed bars
    const cross = new THREE.Group();
    [[1, 0, 0], [0, 1, 0], [0, 0, 1]].forEach((a) => {
      const bar = solid(new THREE.BoxGeometry(a[0] ? 4 * radius : 0.6 * radius, a[1] ? 4 * radius : 0.6 * radius,
                                              a[2] ? 4 * radius : 0.6 * radius), colour);
      cross.add(bar);
    });
    cross.rotation.set(0.6, 0.6, 0);
    cross.position.set(point[0], point[1], point[2]);
    return cross;
  }
  const g = symbol === 'circle' ? new THREE.SphereGeometry(radius, 16, 12) : new THREE.OctahedronGeometry(1.4 * radius);
  const m = solid(g, colour);
  m.position.set(point[0], point[1], point[2]);
  return m;
}
function niceStep(x) {          // 1, 2 or 5 times a power of ten, about x
  const p = Math.pow(10, Math.floor(Math.log10(x))), f = x / p;
  return p * (f < 1.5 ? 1 : f < 3.5 ? 2 : f < 7.5 ? 5 : 10);
}
function build(view) {
  const group = new THREE.Group();
  group.add(solid(geometry(view.surface), 0xb4b4b4));
  const red = still && scene.kind === 'touch';          // Fig. 14: a touch's registered curves in red
  view.curves.forEach((c) => group.add(solid(geometry(c), red ? '#d62728' : c.colour, c.opacity)));
  (view.lines || []).forEach((l) => group.add(solid(geometry(l), l.colour)));
  (view.marks || []).forEach((m) => group.add(dot(m.point, 0.01 * view.size, m.colour, m.symbol)));
  group.add(dot(view.contact, (still ? 0.012 : 0.008) * view.size, still ? '#ffffff' : '#000000', 'circle'));
  return group;
}
function grid(view, up) {         // round squares across the up direction, on the model's far side from the camera
  const lo = view.range[0], hi = view.range[1], step = niceStep(view.size / 10), below = view.look[up.z > 0.5 ? 2 : 1] >= 0;
  const k = up.z > 0.5 ? 2 : 1, across = [0, 1, 2].filter(i => i !== k);
  const cells = 2 * Math.ceil(Math.max(...across.map(i => hi[i] - lo[i])) / 2 / step) + 2;
  const g = new THREE.GridHelper(cells * step, cells, 0xcccccc, 0xe6e6e6);
  if (k === 2) { g.rotation.x = Math.PI / 2; }
  const at = [0, 1, 2].map(i => i === k ? (below ? lo[i] : hi[i]) : 0.5 * (lo[i] + hi[i]));
  g.position.set(at[0], at[1], at[2]);
  return [g, step];
}
function show(index) {
  const view = scene.views[index];
  document.querySelectorAll('#models li').forEach((li, n) => li.classList.toggle('chosen', n === index));
  if (shown) {
    world.remove(shown);
    shown.traverse((o) => { if (o.geometry) { o.geometry.dispose(); } if (o.material) { o.material.dispose(); } });
  }
  const d = new THREE.Vector3(...view.look).normalize(), t = new THREE.Vector3(...view.target);
  const up = Math.abs(d.z) > 0.9 ? new THREE.Vector3(0, 1, 0) : new THREE.Vector3(0, 0, 1);
  shown = build(view);
  const [g, step] = grid(view, up);
  shown.add(g);
  world.add(shown);
  const s = view.surface, units = view.units ? ' ' + view.units : '';
  document.getElementById('note').textContent = (s.faces < s.original_faces
    ? view.model + ': drawn with ' + s.faces + ' of its ' + s.original_faces + ' triangles (decimated for display)'
    : view.model + ': ' + s.faces + ' triangles') + '; grid squares ' + step + units;
  document.getElementById('caption').textContent = view.model + ': error ' + fmt(view.error) + units
    + ', probability ' + fmt(view.probability) + '; grid squares ' + step + units;
  // the whole model in the frame, unless the surface is nearer along the line of sight
  const fit = 0.5 * view.size / Math.sin(Math.PI * camera.fov / 360) * (still ? 0.8 : 1.0);
  const far = Math.min(fit, 0.9 * view.clear * view.size);
  camera.up.copy(up);
  camera.position.copy(t).addScaledVector(d, far);
  camera.near = far / 100;
  camera.far = far + 4 * view.size;
  controls.target.copy(t);
  controls.update();
  resize();
  requestAnimationFrame(drawn);
}
function drawn() {          // once drawn: the time since the page's navigation began, for a benchmark
  if (!document.body.dataset.drawn) { document.body.dataset.drawnMs = performance.now().toFixed(1); }
  document.body.dataset.drawn = 'yes';
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
if (scene.views.length) { show(0); } else { drawn(); }
"""

_STYLE = """
body { margin: 0; font: 14px sans-serif; display: flex; height: 100vh; }
#side { width: 340px; flex: none; padding: 12px; overflow-y: auto; border-right: 1px solid #ddd; box-sizing: border-box; }
#plot { flex: 1; position: relative; overflow: hidden; }
#caption { display: none; position: absolute; top: 10px; width: 100%; text-align: center; font-size: 22px; }
#models { list-style: none; padding: 0; }
#models li { padding: 5px; cursor: pointer; border-radius: 4px; white-space: pre; overflow: hidden; text-overflow: ellipsis; font-size: 13px; }
#models li.chosen { background: #e8eef8; font-weight: bold; }
#models li.other { color: #999; cursor: default; }
#note { color: #666; font-size: 12px; }
#legend { list-style: none; padding: 0; font-size: 13px; }
.swatch { display: inline-block; width: 12px; height: 12px; margin-right: 6px; border-radius: 2px; }
body.still #side { display: none; }
body.still #caption { display: block; }
"""


def library() -> str:
    """The inlined JavaScript: three.js, then its OrbitControls (the licence's text before them)."""
    folder = resources.files("tactrec.viewer") / "vendor"
    parts = {}
    for name, digest in VENDOR.items():
        data = (folder / name).read_bytes()
        if hashlib.sha256(data).hexdigest() != digest:
            raise RuntimeError(f"the viewer's {name} is not the published file (SHA-256 differs): reinstall tactrec")
        parts[name] = data.decode("utf-8")
    notice = parts["three-LICENSE"].replace("*/", "* /")
    return (f"/* three.js 0.147.0 (npm package 'three'): build/three.min.js and\n"
            f"   examples/js/controls/OrbitControls.js, under this licence:\n\n{notice}\n*/\n"
            f"{parts['three.min.js']}\n{parts['OrbitControls.js']}")


def page(scene: dict) -> str:
    """The HTML text of one self-contained page drawing ``scene``."""
    # no <, > or & in the script element, whatever a name holds (JSON.parse reads the escapes back)
    payload = (json.dumps(scene, separators=(",", ":"), allow_nan=False)
               .replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026"))
    heading = scene.get("title") or "tactrec"
    summary = ""
    if scene.get("best") is not None:
        summary = (f"recognised: <b>{html.escape(str(scene['best']))}</b>, confidence "
                   f"{float(scene.get('confidence') or 0):.3f}, unknown {float(scene.get('unknown') or 0):.3f}")
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        f"<title>{html.escape(heading)}</title><style>{_STYLE}</style>"
        f"<script>{library()}</script></head>\n<body>"
        f"<div id=\"side\"><h3>{html.escape(heading)}</h3><p>{summary}</p>"
        "<p>Models (choose one to see its registration; grey: none to show, hover for why):</p><ul id=\"models\"></ul>"
        "<ul id=\"legend\"></ul><p id=\"note\"></p>"
        "<p id=\"help\">Drag to turn, wheel to zoom, right-drag to move.</p></div>"
        "<div id=\"plot\"><div id=\"caption\"></div></div>"
        f"<script type=\"application/json\" id=\"scene\">{payload}</script>"
        f"<script>{_SCRIPT}</script></body></html>\n"
    )
