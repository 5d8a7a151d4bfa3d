"""An overview map of a run as one self-contained HTML file: no external script or style.

The page draws the layers (tracks, GNSS fixes accepted and rejected, outages) on a canvas in
Web-Mercator pixels with a few lines of plain JavaScript: the mouse wheel zooms about the
pointer, dragging pans, a double click fits the whole track again, and the legend's boxes show
or hide a layer.  When the page is served over http(s) and the browser is online, it loads
OpenStreetMap tiles (``https://tile.openstreetmap.org/{z}/{x}/{y}.png``) as the background; when
tiles fail to load and none has loaded (offline, blocked) it falls back to a plain background and
says so.  Opened from a file (``file://``, also inside a report opened from a file) it loads no
tiles: OpenStreetMap's tile usage policy requires a Referer header, which a page opened from a
file cannot send (such requests get "access blocked" tiles); the page says how to serve it.  A scale
bar (1, 2 or 5 x 10^k m, at the view's centre latitude) is shown either way.  The wheel zooms one
level per 500 px of wheel delta (lines and pages converted to px).

Coordinates are geodetic WGS-84 (deg), embedded as JSON (``<script type="application/json"
id="navpp-map-data">``) rounded to 1e-7 deg (about 1 cm).
"""

from __future__ import annotations

import html
import json
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["COORD_DECIMALS", "MapLayer", "decimate_track", "map_data", "map_html"]

#: Decimals of the embedded latitudes and longitudes (deg): 1e-7 deg is about 1 cm.
COORD_DECIMALS = 7
#: Points kept per line layer (stride decimation, the last point always kept).
MAP_POINTS = 4000


@dataclass(frozen=True)
class MapLayer:
    """One layer of the map.

    name : the legend's text; kind : ``"line"`` (each segment a polyline) or ``"points"``
    (markers); color : a CSS colour; segments : ``[(lat_deg (K,), lon_deg (K,)), ...]``
    (WGS-84 deg; a point layer usually has one); width : line width or marker size, px;
    marker : ``"dot"`` or ``"cross"`` (points); visible : shown when the page opens.
    """

    name: str
    kind: str
    color: str
    segments: tuple[tuple[np.ndarray, np.ndarray], ...]
    width: float = 2.0
    marker: str = "dot"
    visible: bool = True


def decimate_track(lat_deg: np.ndarray, lon_deg: np.ndarray, keep: int = MAP_POINTS
                   ) -> tuple[np.ndarray, np.ndarray]:
    """About ``keep`` evenly strided points of a track (non-finite points dropped first, the
    last point always kept)."""
    lat, lon = np.asarray(lat_deg, dtype=float), np.asarray(lon_deg, dtype=float)
    ok = np.isfinite(lat) & np.isfinite(lon)
    lat, lon = lat[ok], lon[ok]
    n = lat.size
    if n <= keep:
        return lat, lon
    idx = np.arange(0, n, -(-n // keep))
    if idx[-1] != n - 1:
        idx = np.append(idx, n - 1)
    return lat[idx], lon[idx]


def _coords(lat: np.ndarray, lon: np.ndarray) -> list[list[float]]:
    lat, lon = np.asarray(lat, dtype=float), np.asarray(lon, dtype=float)
    ok = np.isfinite(lat) & np.isfinite(lon)
    return [[round(float(a), COORD_DECIMALS), round(float(b), COORD_DECIMALS)] for a, b in zip(lat[ok], lon[ok])]


def map_data(layers: Sequence[MapLayer]) -> dict[str, list[dict[str, object]]]:
    """The JSON document the page embeds: ``{"layers": [{name, kind, color, width, marker,
    visible, segments: [[[lat, lon], ...], ...]}, ...]}`` (deg, :data:`COORD_DECIMALS`)."""
    return {"layers": [{"name": ly.name, "kind": ly.kind, "color": ly.color, "width": ly.width,
                        "marker": ly.marker, "visible": ly.visible,
                        "segments": [_coords(a, b) for a, b in ly.segments]} for ly in layers]}


_CSS = """
html, body { height: 100%; }
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 0; color: #222;
       display: flex; flex-direction: column; }
#head { padding: 0.4em 0.8em; font-size: 0.95em; flex: none; }
#wrap { position: relative; flex: 1 1 auto; min-height: 360px; }
#map { position: absolute; left: 0; top: 0; width: 100%; height: 100%; display: block; background: #f4f3ef;
       cursor: grab; touch-action: none; }
#legend { position: absolute; top: 8px; right: 8px; background: rgba(255,255,255,0.92); padding: 6px 10px;
          border: 1px solid #bbb; border-radius: 4px; font-size: 0.85em; }
#legend label { display: block; white-space: nowrap; }
#legend .sw { display: inline-block; width: 18px; height: 4px; margin: 0 6px 3px 4px; vertical-align: middle; }
#status { position: absolute; left: 8px; bottom: 6px; background: rgba(255,255,255,0.85); padding: 2px 6px;
          font-size: 0.8em; }
#scale { position: absolute; right: 16px; bottom: 8px; font-size: 12px; color: #333; text-align: left;
         pointer-events: none; }
#scale-bar { height: 5px; border: 2px solid #333; border-top: none; box-sizing: border-box; }
.note { color: #555; font-size: 0.85em; }
"""

_JS = r"""
(function () {
  var D = JSON.parse(document.getElementById('navpp-map-data').textContent);
  var cv = document.getElementById('map'), ctx = cv.getContext('2d');
  var statusEl = document.getElementById('status'), legend = document.getElementById('legend');
  var scaleBarEl = document.getElementById('scale-bar'), scaleLabelEl = document.getElementById('scale-label');
  // tiles only for a page served over http(s): OpenStreetMap's tile policy requires a Referer,
  // which a page opened from a file cannot send (a report's srcdoc frame: its parent's address)
  function served() {
    var loc = window.location;
    try { if (loc.protocol === 'about:' && window.parent !== window) { loc = window.parent.location; } }
    catch (e) { return false; }
    return loc.protocol === 'http:' || loc.protocol === 'https:';
  }
  var useTiles = served();
  // offline: a tile failed and none has loaded (one failed tile of many does not hide the others)
  var TILE = 256, tiles = {}, tilesBad = 0, tilesOk = 0;
  function offline() { return tilesBad > 0 && tilesOk === 0; }
  function mx(lon) { return (lon + 180) / 360; }
  function my(lat) { var s = Math.sin(lat * Math.PI / 180);
    return 0.5 - Math.log((1 + s) / (1 - s)) / (4 * Math.PI); }
  // every point once in normalised Mercator [0, 1]
  var L = D.layers.map(function (ly) { return { src: ly, segs: ly.segments.map(function (seg) {
    return seg.map(function (p) { return [mx(p[1]), my(p[0])]; }); }) }; });
  var view = { cx: 0.5, cy: 0.5, z: 2 };
  function size() { var r = cv.getBoundingClientRect(), d = window.devicePixelRatio || 1;
    cv.width = Math.round(r.width * d); cv.height = Math.round(r.height * d); ctx.setTransform(d, 0, 0, d, 0, 0);
    return r; }
  function fit() {
    var x0 = 1, x1 = 0, y0 = 1, y1 = 0;
    L.forEach(function (l) { l.segs.forEach(function (s) { s.forEach(function (p) {
      x0 = Math.min(x0, p[0]); x1 = Math.max(x1, p[0]); y0 = Math.min(y0, p[1]); y1 = Math.max(y1, p[1]); }); }); });
    if (x1 < x0) { return; }
    var r = cv.getBoundingClientRect();
    view.cx = (x0 + x1) / 2; view.cy = (y0 + y1) / 2;
    var span = Math.max((x1 - x0) / r.width, (y1 - y0) / r.height, 1e-12);
    view.z = Math.min(Math.log2(0.9 / (span * TILE)), 21);
  }
  function scale() { return TILE * Math.pow(2, view.z); }
  function toPx(p, r) {
    var s = scale(); return [(p[0] - view.cx) * s + r.width / 2, (p[1] - view.cy) * s + r.height / 2];
  }
  function tile(z, x, y) {
    var k = z + '/' + x + '/' + y;
    if (!tiles[k]) {
      var img = new Image();
      img.onload = function () { tilesOk += 1; draw(); };
      img.onerror = function () { tilesBad += 1; draw(); };
      img.referrerPolicy = 'strict-origin-when-cross-origin';   // the page's origin: what the policy asks
      img.src = 'https://tile.openstreetmap.org/' + k + '.png';
      tiles[k] = img;
    }
    return tiles[k];
  }
  function drawTiles(r) {
    var zi = Math.max(0, Math.min(19, Math.round(view.z))), n = Math.pow(2, zi), s = scale(), ts = s / n;
    var xa = Math.floor((view.cx - r.width / 2 / s) * n), xb = Math.floor((view.cx + r.width / 2 / s) * n);
    var ya = Math.max(0, Math.floor((view.cy - r.height / 2 / s) * n));
    var yb = Math.min(n - 1, Math.floor((view.cy + r.height / 2 / s) * n));
    if ((xb - xa + 1) * (yb - ya + 1) > 400) { return; }
    for (var x = xa; x <= xb; x++) { for (var y = ya; y <= yb; y++) {
      var img = tile(zi, ((x % n) + n) % n, y);
      if (img.complete && img.naturalWidth) {
        var p = toPx([x / n, y / n], r); ctx.drawImage(img, p[0], p[1], ts + 0.5, ts + 0.5);
      }
    } }
  }
  function scaleBar() {   // the longest 1, 2 or 5 x 10^k m that fits in 120 px, at the view's centre
    var lat = Math.atan(Math.sinh(Math.PI * (1 - 2 * view.cy)));
    var mPerPx = 40075016.686 * Math.cos(lat) / scale();
    var target = mPerPx * 120, e = Math.pow(10, Math.floor(Math.log10(target))), m = e;
    [1, 2, 5, 10].forEach(function (f) { if (f * e <= target) { m = f * e; } });
    m = Number(m.toPrecision(1));
    scaleBarEl.style.width = (m / mPerPx).toFixed(1) + 'px';
    scaleLabelEl.textContent = m >= 1000 ? (m / 1000) + ' km' : m + ' m';
  }
  function draw() {
    var r = size();
    ctx.fillStyle = '#f4f3ef'; ctx.fillRect(0, 0, r.width, r.height);
    if (useTiles && !offline()) { drawTiles(r); }
    L.forEach(function (l) {
      if (!l.src.visible) { return; }
      ctx.strokeStyle = l.src.color; ctx.fillStyle = l.src.color; ctx.lineWidth = l.src.width;
      l.segs.forEach(function (seg) {
        if (l.src.kind === 'line') {
          ctx.beginPath();
          seg.forEach(function (p, i) {
            var q = toPx(p, r); if (i) { ctx.lineTo(q[0], q[1]); } else { ctx.moveTo(q[0], q[1]); }
          });
          ctx.stroke();
        } else {
          var h = l.src.width;
          seg.forEach(function (p) { var q = toPx(p, r);
            if (q[0] < -h || q[1] < -h || q[0] > r.width + h || q[1] > r.height + h) { return; }
            if (l.src.marker === 'cross') { ctx.lineWidth = 1.5; ctx.beginPath();
              ctx.moveTo(q[0] - h, q[1] - h); ctx.lineTo(q[0] + h, q[1] + h);
              ctx.moveTo(q[0] - h, q[1] + h); ctx.lineTo(q[0] + h, q[1] - h); ctx.stroke();
            } else { ctx.beginPath(); ctx.arc(q[0], q[1], h / 2, 0, 2 * Math.PI); ctx.fill(); } });
        }
      });
    });
    scaleBar();
    statusEl.innerHTML = !useTiles ? 'plain background: map tiles need this page served over http '
      + '(<code>python3 -m http.server</code> in its folder), as OpenStreetMap\'s tile policy asks'
      : offline() ? 'offline: plain background (map tiles could not be loaded)'
      : (tilesOk ? 'background &copy; <a href="https://www.openstreetmap.org/copyright">OpenStreetMap</a> contributors'
                 : 'loading map tiles ...');
  }
  D.layers.forEach(function (ly, i) {
    var lab = document.createElement('label'), box = document.createElement('input');
    var sw = document.createElement('span');
    box.type = 'checkbox'; box.checked = ly.visible;
    box.onchange = function () { ly.visible = box.checked; draw(); };
    sw.className = 'sw'; sw.style.background = ly.color;
    if (ly.kind !== 'line') { sw.style.height = '8px'; sw.style.width = '8px'; sw.style.borderRadius = '4px'; }
    lab.appendChild(box); lab.appendChild(sw); lab.appendChild(document.createTextNode(ly.name));
    legend.appendChild(lab);
  });
  var drag = null;
  cv.addEventListener('wheel', function (ev) {
    ev.preventDefault();
    var r = cv.getBoundingClientRect(), s = scale();
    var px = ev.clientX - r.left - r.width / 2, py = ev.clientY - r.top - r.height / 2;
    var wx = view.cx + px / s, wy = view.cy + py / s;
    // 500 px of wheel = one zoom level; deltaMode 1 (lines, Firefox) and 2 (pages) in px
    var dy = ev.deltaY * (ev.deltaMode === 1 ? 40 : ev.deltaMode === 2 ? r.height : 1);
    view.z = Math.max(0, Math.min(23, view.z - dy * 0.002));
    s = scale(); view.cx = wx - px / s; view.cy = wy - py / s; draw();
  }, { passive: false });
  cv.addEventListener('pointerdown', function (ev) {
    drag = [ev.clientX, ev.clientY]; cv.setPointerCapture(ev.pointerId); cv.style.cursor = 'grabbing';
  });
  cv.addEventListener('pointermove', function (ev) {
    if (!drag) { return; }
    var s = scale(); view.cx -= (ev.clientX - drag[0]) / s; view.cy -= (ev.clientY - drag[1]) / s;
    drag = [ev.clientX, ev.clientY]; draw();
  });
  cv.addEventListener('pointerup', function () { drag = null; cv.style.cursor = 'grab'; });
  cv.addEventListener('dblclick', function () { fit(); draw(); });
  window.addEventListener('resize', draw);
  size(); fit(); draw();
})();
"""


def map_html(title: str, layers: Sequence[MapLayer], notes: Sequence[str] = ()) -> str:
    """The self-contained HTML page of the map (see the module docstring); ``notes``: lines
    shown under the title."""
    e = html.escape
    data = json.dumps(map_data(layers), separators=(",", ":")).replace("</", "<\\/")
    out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
           '<meta name="viewport" content="width=device-width, initial-scale=1">',
           f"<title>{e(title)}</title>", f"<style>{_CSS}</style>", "</head>", "<body>",
           f'<div id="head"><b>{e(title)}</b>']
    out += [f'<div class="note">{e(n)}</div>' for n in notes]
    out += ['<div class="note">Wheel: zoom; drag: pan; double click: whole track; the boxes show or hide a '
            "layer. Positions WGS-84.</div></div>",
            '<div id="wrap"><canvas id="map"></canvas><div id="legend"></div><div id="status"></div>'
            '<div id="scale"><span id="scale-label"></span><div id="scale-bar"></div></div></div>',
            f'<script type="application/json" id="navpp-map-data">{data}</script>',
            f"<script>{_JS}</script>", "</body>", "</html>"]
    return "\n".join(out) + "\n"
