"""The overview map (:mod:`navpp.mapview`) in a real browser: headless Chromium (:mod:`headless`).

A synthetic L-shaped track (1000 m east, then 600 m north, built with navpp's exact ENU to
geodetic conversion) is the oracle: the fitted view has the track's Web-Mercator aspect ratio
and fills 90 % of the map; the scale bar's length over its label is the metres per pixel of the
drawn 1000 m leg; the mouse wheel scales the drawing about the pointer by 2^(-deltaY/500); a
drag moves it by the drag; the legend's box hides a layer; a double click fits again.  The page
is served over http by the test itself (Chromium resolves no host names): with the tile requests
failing it says it is offline; with tiles served it draws them, names OpenStreetMap, and its tile
requests carry the Referer OpenStreetMap's tile policy requires.  Opened from a file it requests
no tile (it could send no Referer) and says how to serve it.  Skipped when no Chromium is installed.
"""

from __future__ import annotations

import json
import re
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from headless import Browser, chromium_path

from navpp.geodesy import enu_to_geodetic
from navpp.mapview import MapLayer, map_html

CHROMIUM = chromium_path()
pytestmark = [pytest.mark.skipif(CHROMIUM is None, reason="no Chromium installed (apt-get install chromium, "
                                                          "or set NAVPP_CHROMIUM)"),
              pytest.mark.slow]

LAT0_DEG, LON0_DEG = 48.1, 11.5
EAST_M, NORTH_M = 1000.0, 600.0
COLORS = {"fixes": (0x77, 0x77, 0x77), "track": (0x1F, 0x77, 0xB4), "outage": (0xFF, 0x8C, 0x00),
          "rejected": (0xD6, 0x27, 0x28)}
BACKGROUND = (0xF4, 0xF3, 0xEF)
TILE_RGB = (0x9A, 0xCD, 0x32)
TRACK_WIDTH_PX = 2.0
SITE = "http://navpp.test/"
TILES = "https://tile.openstreetmap.org/"
CANVAS_JS = r"""
(function (doc, cols, tol) {
  var cv = doc.getElementById('map'), W = cv.width, H = cv.height;
  var d = cv.getContext('2d').getImageData(0, 0, W, H).data;
  var out = cols.map(function () { return {n: 0, x0: 1e9, x1: -1, y0: 1e9, y1: -1}; });
  for (var i = 0; i < d.length; i += 4) {
    for (var k = 0; k < cols.length; k++) {
      var c = cols[k];
      if (Math.abs(d[i] - c[0]) <= tol && Math.abs(d[i + 1] - c[1]) <= tol && Math.abs(d[i + 2] - c[2]) <= tol) {
        var p = i / 4, x = p % W, y = (p - x) / W, o = out[k];
        o.n++; o.x0 = Math.min(o.x0, x); o.x1 = Math.max(o.x1, x); o.y0 = Math.min(o.y0, y); o.y1 = Math.max(o.y1, y);
        break;
      }
    }
  }
  var r = cv.getBoundingClientRect();
  return {w: W, h: H, left: r.left, top: r.top, cols: out};
})(DOC, COLS, TOL)
"""


def _enu_track(points_enu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lat, lon, _ = enu_to_geodetic(points_enu, np.radians(LAT0_DEG), np.radians(LON0_DEG), 0.0)
    return np.degrees(lat), np.degrees(lon)


def _layers() -> list[MapLayer]:
    east = np.stack([np.linspace(0, EAST_M, 101), np.zeros(101), np.zeros(101)], axis=1)
    north = np.stack([np.full(61, EAST_M), np.linspace(0, NORTH_M, 61), np.zeros(61)], axis=1)
    track = _enu_track(np.concatenate([east, north[1:]]))
    fixes = _enu_track(np.concatenate([east[::10], north[10::10]]) + [0.0, 0.0, 0.0])
    outage = _enu_track(north[20:40])
    rejected = _enu_track(np.array([[300.0, 0.0, 0.0], [EAST_M, 450.0, 0.0]]))
    hx = "#%02x%02x%02x"
    return [MapLayer("GNSS fixes", "points", hx % COLORS["fixes"], (fixes,), width=8.0),
            MapLayer("ekf", "line", hx % COLORS["track"], (track,), width=TRACK_WIDTH_PX),
            MapLayer("GNSS outages (1)", "line", hx % COLORS["outage"], (outage,), width=6.0),
            MapLayer("rejected fixes (2)", "points", hx % COLORS["rejected"], (rejected,), width=5.0,
                     marker="cross")]


def _mercator(lat_deg: np.ndarray, lon_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised Web-Mercator x, y in [0, 1] (y down), the textbook form."""
    lat = np.radians(lat_deg)
    return (np.asarray(lon_deg) + 180.0) / 360.0, 0.5 - np.log(np.tan(np.pi / 4 + lat / 2)) / (2 * np.pi)


def _png(rgb: tuple[int, int, int], size: int = 256) -> bytes:
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    raw = b"".join(b"\x00" + bytes(rgb) * size for _ in range(size))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", size, size, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


@pytest.fixture(scope="module")
def map_page(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("map") / "synthetic_map.html"
    path.write_text(map_html("synthetic: overview map", _layers(), ["an L: 1000 m east, 600 m north"]),
                    encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def browser():
    assert CHROMIUM is not None
    with Browser(CHROMIUM) as b:
        yield b


def _serve(page, files: dict[str, bytes], tile: bytes | None) -> None:
    """Answer the page's requests: ``SITE + name`` with ``files[name]``, tiles with ``tile``
    (a PNG; None: as if offline), anything else as unresolved."""
    def answer(url: str) -> tuple[int, str, bytes] | None:
        if url.startswith(SITE) and url[len(SITE):] in files:
            return 200, "text/html; charset=utf-8", files[url[len(SITE):]]
        if url.startswith(TILES) and tile is not None:
            return 200, "image/png", tile
        return None

    page.serve("*", answer)


def _tile_requests(page) -> list[tuple[str, dict[str, str]]]:
    return [(u, h) for u, h in page.requests if u.startswith(TILES)]


def _pixels(page, colors: dict[str, tuple[int, int, int]] = COLORS, tol: int = 12, doc: str = "document") -> dict:
    """The map canvas's size and position, and per colour its pixel count and bounding box (px);
    ``doc``: the JavaScript expression of the map's document."""
    res = page.js(CANVAS_JS.replace("COLS", json.dumps([list(c) for c in colors.values()]))
                  .replace("TOL", str(tol)).replace("DOC", doc))
    res["by"] = dict(zip(colors, res.pop("cols")))
    return res


def _scale_bar(page) -> tuple[float, float]:
    """The scale bar's (label in m, length in px)."""
    label = page.js("document.getElementById('scale-label').textContent")
    m = re.fullmatch(r"(\d+(?:\.\d+)?) (m|km)", label)
    assert m is not None, label
    assert re.fullmatch(r"0*\.?0*[125]0*\.?0*", m.group(1)), label      # 1, 2 or 5 x 10^k
    bar_px = page.js("document.getElementById('scale-bar').getBoundingClientRect().width")
    return float(m.group(1)) * (1000.0 if m.group(2) == "km" else 1.0), float(bar_px)


def _centre(box: dict) -> np.ndarray:
    return np.array([(box["x0"] + box["x1"]) / 2, (box["y0"] + box["y1"]) / 2])


def _size(box: dict) -> np.ndarray:
    return np.array([box["x1"] - box["x0"] + 1, box["y1"] - box["y0"] + 1], dtype=float)


def _legend_box(page, name: str) -> tuple[float, float]:
    r = page.js("(function () { var l = Array.from(document.querySelectorAll('#legend label')).find("
                f"function (l) {{ return l.textContent.indexOf({name!r}) >= 0; }}); "
                "var b = l.querySelector('input').getBoundingClientRect(); "
                "return [b.left + b.width / 2, b.top + b.height / 2]; })()")
    return float(r[0]), float(r[1])


def test_map_offline_draws_fits_scales_zooms_pans_and_toggles(browser, map_page: Path):
    page = browser.page(1100, 760)
    _serve(page, {"map.html": map_page.read_bytes()}, tile=None)
    page.goto(SITE + "map.html", settle_s=0.6)
    assert page.errors == []
    assert _tile_requests(page)                          # it tried, they failed
    assert page.js("document.getElementById('status').textContent").startswith("offline: plain background")
    px = _pixels(page)
    by, w, h = px["by"], px["w"], px["h"]
    assert w == 1100 and h >= 360
    for name, box in by.items():
        assert box["n"] > 10, name                       # every layer drew
    # the fitted view: every layer inside the track's box, which has the Web-Mercator aspect
    # ratio of the data and spans 90 % of the limiting dimension, centred
    lat, lon = _layers()[1].segments[0]
    mx, my = _mercator(lat, lon)
    ex, ey = np.ptp(mx), np.ptp(my)
    s = 0.9 / max(ex / w, ey / h)                        # px per normalised Mercator unit
    track = by["track"]
    drawn = _size(track) - TRACK_WIDTH_PX
    np.testing.assert_allclose(drawn, [ex * s, ey * s], atol=2.0)
    np.testing.assert_allclose(_centre(track), [(w - 1) / 2, (h - 1) / 2], atol=1.5)
    # the scale bar: its length x the drawn leg's metres per pixel is its label
    label_m, bar_px = _scale_bar(page)
    m_per_px = EAST_M / drawn[0]
    assert bar_px * m_per_px == pytest.approx(label_m, rel=0.01)
    assert 120 / 2.5 < bar_px <= 120                    # the longest 1-2-5 length within 120 px

    # the legend's box hides a layer: no orange left, the track and fixes under it show
    page.click(*_legend_box(page, "GNSS outages"))
    after = _pixels(page)["by"]
    assert after["outage"]["n"] == 0 and after["track"]["n"] > track["n"]
    assert after["fixes"]["n"] >= by["fixes"]["n"] and after["rejected"]["n"] == by["rejected"]["n"]
    page.click(*_legend_box(page, "GNSS outages"))
    assert _pixels(page)["by"]["outage"]["n"] == by["outage"]["n"]

    # wheel: 500 px down is one level out, about the pointer
    left, top = px["left"], px["top"]
    pointer = np.array([300.0, 200.0])
    page.wheel(left + pointer[0], top + pointer[1], 500.0)
    out = _pixels(page)["by"]["track"]
    np.testing.assert_allclose(_centre(out), pointer + 0.5 * (_centre(track) - pointer), atol=1.5)
    np.testing.assert_allclose(_size(out) - TRACK_WIDTH_PX, 0.5 * drawn, atol=2.0)
    label_m, bar_px = _scale_bar(page)
    assert bar_px * 2 * m_per_px == pytest.approx(label_m, rel=0.01)
    # drag: the drawing follows the mouse
    page.drag(left + 500, top + 300, left + 560, top + 340)
    moved = _pixels(page)["by"]["track"]
    np.testing.assert_allclose(_centre(moved), _centre(out) + [60, 40], atol=1.0)
    np.testing.assert_allclose(_size(moved), _size(out), atol=1.0)
    # double click: the whole track again, as at the start
    page.click(left + 400, top + 100, count=2)
    again = _pixels(page)["by"]["track"]
    np.testing.assert_allclose([again["x0"], again["x1"], again["y0"], again["y1"]],
                               [track["x0"], track["x1"], track["y0"], track["y1"]], atol=1.0)
    assert page.errors == []


def test_map_online_draws_served_tiles_under_the_track(browser, map_page: Path, tmp_path: Path):
    page = browser.page(1100, 760)
    _serve(page, {"map.html": map_page.read_bytes()}, tile=_png(TILE_RGB))
    page.goto(SITE + "map.html", settle_s=0.8)
    assert page.errors == [] and [u for u in page.failed_loads if not u.endswith("/favicon.ico")] == []
    assert "OpenStreetMap" in page.js("document.getElementById('status').textContent")
    tiles = _tile_requests(page)
    assert tiles and all(h.get("Referer") == SITE for _, h in tiles), tiles[:2]
    # the canvas now holds cross-origin tiles (unreadable from the page): read a screenshot of it
    from matplotlib.image import imread

    box = page.js("(function () { var r = document.getElementById('map').getBoundingClientRect(); "
                  "return [r.left, r.top, r.width, r.height]; })()")
    shot = tmp_path / "online.png"
    page.screenshot(shot)
    x, y, w, h = (int(round(v)) for v in box)
    rgb = np.round(imread(shot)[y:y + h, x:x + w, :3] * 255).astype(int)

    def count(c: tuple[int, int, int]) -> int:
        return int(np.all(np.abs(rgb - c) <= 2, axis=-1).sum())

    assert count(COLORS["track"]) > 100 and count(COLORS["outage"]) > 10
    # the tiles are the background (all but the layers, the legend and the notes), the plain one is gone
    assert count(TILE_RGB) > 0.8 * w * h and count(BACKGROUND) == 0
    # the requested tiles are those under the track at the view's zoom
    zxy = {tuple(int(v) for v in re.search(r"/(\d+)/(\d+)/(\d+)\.png$", u).groups()) for u, _ in tiles}
    zooms = {z for z, _, _ in zxy}
    assert len(zooms) == 1
    z = zooms.pop()
    lat, lon = _layers()[1].segments[0]
    mx, my = _mercator(lat, lon)
    for x, y in zip(mx[[0, -1]], my[[0, -1]]):          # the track's ends
        assert (z, int(x * 2 ** z), int(y * 2 ** z)) in zxy


def test_map_from_a_file_requests_no_tiles_and_says_why(browser, map_page: Path):
    page = browser.page(1100, 760)
    _serve(page, {}, tile=_png(TILE_RGB))                # tiles would be there: none is asked for
    page.goto(map_page, settle_s=0.5)
    assert page.errors == [] and _tile_requests(page) == []
    status = page.js("document.getElementById('status').textContent")
    assert status.startswith("plain background: map tiles need this page served over http"), status
    assert all(box["n"] > 10 for box in _pixels(page)["by"].values())


def test_compare_report_shows_its_figures_and_the_map(browser, map_page: Path, tmp_path: Path):
    """The report (:func:`navpp.comparison.report.write_report`) with a PNG figure and the map:
    the image decodes at its size, the map inside the report's frame draws every layer."""
    from navpp.comparison.figures import Plot
    from navpp.comparison.report import write_report
    from navpp.comparison.rows import CompareRow

    png = _png((0x20, 0x40, 0x60), size=64)
    plots = [Plot("synthetic_trajectory.png", "synthetic: trajectories", png),
             Plot("synthetic_map.html", "synthetic: overview map", map_page.read_bytes())]
    write_report(tmp_path, [CompareRow("synthetic", "ekf", "ok", None, 10, 0, 0.1, 100)], {"synthetic": plots})
    page = browser.page(1240, 1000)
    _serve(page, {"report.html": (tmp_path / "report.html").read_bytes()}, tile=_png(TILE_RGB))
    page.goto(tmp_path / "report.html", settle_s=0.8)
    assert page.errors == []
    images = page.js("Array.from(document.images).map(function (i) { return [i.alt, i.naturalWidth]; })")
    assert images == [["synthetic: trajectories", 64]]
    frame = "document.querySelector('iframe').contentDocument"
    px = _pixels(page, doc=frame)
    assert px["w"] > 1000 and px["h"] >= 360
    assert all(box["n"] > 10 for box in px["by"].values()), px["by"]
    assert page.js(f"{frame}.getElementById('status').textContent").startswith("plain background")
    assert _tile_requests(page) == []
    # the map fills its frame: the frame's height is the page's (header and map), no gap below
    heights = page.js(f"[document.querySelector('iframe').clientHeight, {frame}.documentElement.scrollHeight, "
                      f"{frame}.getElementById('wrap').getBoundingClientRect().bottom]")
    assert heights[1] == heights[0] and heights[2] == pytest.approx(heights[0], abs=1)
    # served over http, the map in the report's frame loads tiles with the report's origin as Referer
    page.goto(SITE + "report.html", settle_s=0.8)
    assert page.errors == [] and "OpenStreetMap" in page.js(f"{frame}.getElementById('status').textContent")
    tiles = _tile_requests(page)
    assert tiles and all(h.get("Referer") == SITE for _, h in tiles)
