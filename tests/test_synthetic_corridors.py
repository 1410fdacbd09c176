"""The synthetic corridor variants: their geometry and the mobile scanner's thinning."""



import numpy as np
import pytest


def test_corridor_variants_have_their_geometry():
    """Stacked circuits hang three phases one above another at each plan offset; a hillside
    corridor's ground rises by its slope; a 400 m span is strung so its sag keeps half the
    attachment height clear."""
    from toolbox_plugins.synthetic_scene.generator.scene import make_scene

    st = make_scene("corridor", 1, density_ppm2=1.0, line_variant="stacked")
    a = [w for w in st.truth["wires"] if w["line"] == "A" and w["kind"] == "phase"]
    per_offset = {}
    for w in a:
        per_offset.setdefault(round(w["offset_m"], 3), []).append(w)
    assert len({round(w["offset_m"], 3) for w in a}) == 4  # two circuits x two sub-conductors across
    assert all(len(v) == 3 for v in per_offset.values())
    hill = make_scene("corridor", 1, density_ppm2=1.0, slope_pct=25.0)
    flat = make_scene("corridor", 1, density_ppm2=1.0)
    rise = (hill.dtm - flat.dtm)[:, -1].mean() - (hill.dtm - flat.dtm)[:, 0].mean()
    assert rise == pytest.approx(0.25 * (hill.dtm.shape[1] - 1) * hill.dtm_resolution_m, rel=1e-3)
    long_ = make_scene("corridor", 1, density_ppm2=1.0, span_m=400.0, width_m=1000.0)
    spans = [s for s in long_.truth["spans"] if s["line"] == "A"]
    assert max(s["length_m"] for s in spans) > 390
    ox, oy = long_.origin
    for s in spans:  # the lower arms' wires hang 17.5 m up: at least half that over the ground
        c = np.array(s["curve"])
        assert np.min(c[:, 2] - long_.terrain.height(c[:, 0] - ox, c[:, 1] - oy)) >= 0.5 * 17.5 - 0.2



def test_mobile_scanner_scene_thins_with_range():
    """scanner=mobile: a track 2 m over the ground beside line A; points kept with probability
    min(1, (10 m / range)^2): the density within 10 m of the scanner is the one asked for, at
    30 m a ninth of it, and the wires overhead keep their points near the track."""
    from toolbox_plugins.synthetic_scene.generator.scene import make_scene

    sc = make_scene("corridor", 2, density_ppm2=100.0, width_m=200.0, height_m=120.0, line_variant="distribution",
                    scanner="mobile")
    (x0, y0), (x1, y1) = sc.truth["scanner"]["track"]
    d = np.array([x1 - x0, y1 - y0]) / np.hypot(x1 - x0, y1 - y0)
    lateral = np.abs((sc.x - x0) * -d[1] + (sc.y - y0) * d[0])
    first = sc.fields["return_number"] == 1  # one per pulse

    def density(lo, hi):  # pulses per m² in a band beside the track, its middle 80 % along the scene
        along = (sc.x - x0) * d[0] + (sc.y - y0) * d[1]
        m = first & (lateral >= lo) & (lateral < hi)
        a = along[m]
        return np.sum((a > np.percentile(a, 10)) & (a < np.percentile(a, 90))) / (0.8 * np.ptp(a) * 2 * (hi - lo))
    near, far = density(0.0, 5.0), density(29.0, 31.0)
    assert near == pytest.approx(100.0, rel=0.15)
    assert far == pytest.approx(100.0 * (10.0 / np.hypot(30.0, 2.0)) ** 2, rel=0.25)
    spans = [s for s in sc.truth["spans"] if s["line"] == "A"]
    assert all(s["n_points"] > 0 for s in spans)
    with pytest.raises(ValueError, match="mobile"):
        make_scene("terrain", 1, scanner="mobile")
