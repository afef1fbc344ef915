"""OsmMap: the CLI's counts, arrays in the local frame, GeoJSON that follows RFC 7946."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import urbansem


@pytest.fixture(scope="module")
def kth(data: Path) -> urbansem.OsmMap:
    return urbansem.OsmMap.load(data / "osm" / "kth_campus_stockholm.osm")


def test_counts_equal_the_cli(kth: urbansem.OsmMap, data: Path, cli) -> None:
    info = cli("osm", "info", data / "osm" / "kth_campus_stockholm.osm", "--json", json_out=True)
    assert kth.building_count == len(kth.buildings) == info["building_outlines"]
    assert kth.segments.shape == (info["segments"], 4)
    assert len(kth.streets) == info["highway_ways"]
    assert kth.intersections.shape == (info["intersections"], 2)
    assert kth.origin == pytest.approx(tuple(info["frame_origin_lat_lon"]))


def test_arrays_are_consistent(kth: urbansem.OsmMap) -> None:
    for ring in kth.buildings:
        assert ring.ndim == 2 and ring.shape[1] == 2 and len(ring) >= 3
        x, y = ring[:, 0], ring[:, 1]
        area = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
        assert area > 0  # counter-clockwise
    seg = kth.segments
    assert len(kth.segment_highways) == len(seg) == len(kth.segment_ways)
    # Every segment lies on its way's centre line: its ends are vertices of some street.
    vertices = {tuple(np.round(p, 6)) for line in kth.streets for p in line}
    assert all(tuple(np.round(s[:2], 6)) in vertices for s in seg)


def test_frame_round_trip(kth: urbansem.OsmMap) -> None:
    xy = np.array([[0.0, 0.0], [120.5, -80.25], [-300.0, 410.0]])
    ll = kth.to_wgs84(xy)
    assert ll[0] == pytest.approx(kth.origin)
    assert np.abs(kth.to_local(ll) - xy).max() < 1e-6


def test_geojson_follows_rfc7946(kth: urbansem.OsmMap) -> None:
    g = kth.to_geojson()
    assert g["type"] == "FeatureCollection" and "OpenStreetMap" in g["attribution"]
    polys = [f for f in g["features"] if f["geometry"]["type"] == "Polygon"]
    lines = [f for f in g["features"] if f["geometry"]["type"] == "LineString"]
    assert len(polys) == kth.building_count and len(lines) == len(kth.streets)
    min_lon, min_lat, max_lon, max_lat = kth.bbox_lonlat
    for f in polys:
        for r, ring in enumerate(f["geometry"]["coordinates"]):
            p = np.array(ring)
            assert len(p) >= 4 and np.array_equal(p[0], p[-1])
            area = 0.5 * np.sum(p[:-1, 0] * p[1:, 1] - p[1:, 0] * p[:-1, 1])
            assert (area > 0) == (r == 0)  # exterior counter-clockwise, holes clockwise
            assert np.all((p[:, 0] > min_lon - 0.01) & (p[:, 0] < max_lon + 0.01))
            assert np.all((p[:, 1] > min_lat - 0.01) & (p[:, 1] < max_lat + 0.01))
    # Positions are [lon, lat] of the local outline.
    first = np.array(polys[0]["geometry"]["coordinates"][0])[:-1]
    back = kth.to_local(first[:, ::-1])
    ring = kth.buildings[0]
    assert min(np.abs(back - q).sum(axis=1).min() for q in ring) < 1e-6


def test_missing_and_malformed_maps(tmp_path: Path) -> None:
    with pytest.raises(urbansem.OsmError, match="missing.osm"):
        urbansem.OsmMap.load(tmp_path / "missing.osm")
    bad = tmp_path / "bad.osm"
    bad.write_text("<osm version='0.6'><node id='1' lat='x' lon='2'/></osm>")
    with pytest.raises(urbansem.OsmError, match="bad.osm"):
        urbansem.OsmMap.load(bad)
