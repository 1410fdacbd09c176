"""tophat: the point filter and its raster twin."""



import numpy as np
import pytest
from toolbox_plugins.tophat.core import tophat_points, tophat_raster


def test_tophat_keeps_lines_and_drops_blobs_and_dense_cells():
    rng = np.random.default_rng(0)
    wire_x = np.linspace(0, 50, 200)
    wire = np.column_stack([wire_x, 10 + 0.0 * wire_x])
    blob = rng.uniform([20, 30], [30, 40], (3000, 2))  # a crown / a roof
    x = np.r_[wire[:, 0], blob[:, 0]]
    y = np.r_[wire[:, 1], blob[:, 1]]
    cx, cy, _, counts, _ = tophat_points(x, y, 0.5, 45)
    on_wire = np.abs(cy - 10) < 0.5
    assert on_wire.sum() >= 90  # about 2 centroids per metre of wire
    assert (~on_wire).sum() < 0.1 * on_wire.sum()  # the blob's interior is gone
    # a dense thin structure (>= 45 points per cell) is dropped as vegetation
    cx2, *_ = tophat_points(np.repeat(wire_x, 50), np.full(200 * 50, 10.0), 0.5, 45)
    assert len(cx2) == 0
    img = np.zeros((20, 20))
    img[5, 2:18] = 1
    img[10:16, 10:16] = 1
    th = tophat_raster(img, "binary")
    assert th[5, 3:17].all() and th[12, 12] == 0



@pytest.mark.parametrize("shape, size", [("cross", 3), ("square", 3), ("disk", 5), ("cross", 4)])
def test_sparse_tophat_equals_the_raster_opening(shape, size):
    """The opening on occupied cells only gives the cells scipy's binary_opening of the mask does."""
    from scipy import ndimage
    from toolbox_plugins.tophat.core import structure

    rng = np.random.default_rng(size)
    pts = np.r_[rng.uniform(0, 30, (3000, 2)), rng.uniform(5, 9, (4000, 2)),
                np.column_stack([np.linspace(0, 30, 400), np.full(400, 20.0)])]
    x, y = pts[:, 0], pts[:, 1]
    el = structure(shape, size)
    cx, cy, cz, counts, kept_point = tophat_points(x, y, 0.5, 45, el, z=x + y)
    # the dense reference on a raster with a wide margin
    c = np.floor(x / 0.5).astype(int) + 10
    r = np.floor(y / 0.5).astype(int) + 10
    n = np.zeros((r.max() + 11, c.max() + 11), int)
    np.add.at(n, (r, c), 1)
    mask = n > 0
    keep = mask & ~ndimage.binary_opening(mask, structure=el) & (n < 45)
    assert np.array_equal(kept_point, keep[r, c])
    assert len(cx) == keep.sum() and counts.sum() == kept_point.sum()
    np.testing.assert_allclose(np.sort(cz), np.sort(cx + cy))  # means of x + y per cell
