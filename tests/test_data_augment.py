"""Mirroring and yaw against the geometry they claim."""

import math

import numpy as np
import pytest

from crossing_assist.actions import heading_to_x, x_to_bin, x_to_heading
from crossing_assist.data_tools.augment import (
    intrinsics, mirror, random_yaw, yaw, yaw_homography, yaw_label, yaw_x,
)

W, H = 96, 48


def _line_image(x: float) -> np.ndarray:
    """A frame with one bright vertical line at fraction x of the width."""
    img = np.zeros((H, W, 3), np.uint8)
    img[:, int(x * W)] = 255
    return img


def test_mirror_twice_is_identity():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    for x, b in [(0.1, 2), (0.5, 7), (0.99, 12), (None, 0), (None, 5)]:
        m_img, m_x, m_b = mirror(img, x, b)
        assert m_b == (0 if b == 0 else 13 - b)
        assert (m_x is None) == (x is None) and (x is None or m_x == pytest.approx(1 - x))
        back = mirror(m_img, m_x, m_b)
        np.testing.assert_array_equal(back[0], img)
        assert back[2] == b and (x is None or back[1] == pytest.approx(x))
    assert mirror(img, 0.1, 2)[0][0, -1].tolist() == img[0, 0].tolist()


def test_label_moves_by_the_pinhole_formula():
    fov = 90.0
    for x, psi in [(0.5, 10.0), (0.3, -20.0), (0.8, 25.0)]:
        expected = 0.5 + math.tan(math.atan((2 * x - 1) * math.tan(math.radians(fov / 2))) - math.radians(psi)) / 2
        assert yaw_x(x, psi, fov) == pytest.approx(expected, abs=1e-12)
    # turning right moves the goal left
    assert yaw_x(0.5, 10.0) < 0.5 < yaw_x(0.5, -10.0)


def test_image_and_label_move_together():
    x = 0.7
    img = _line_image(x)
    x_pix = int(x * W)  # the line's pixel column
    for psi in (12.0, -12.0, 30.0):
        out, new_x, new_b, valid = yaw(img, (x_pix + 0.5) / W, 9, psi)
        col = int(np.argmax(out[H // 2, :, 0]))
        assert abs((col + 0.5) / W - new_x) <= 1.0 / W, (psi, col, new_x)
        assert new_b == x_to_bin(new_x)
        # the homography K R K^-1 agrees with the label formula
        p = yaw_homography(W, H, psi) @ np.array([x_pix, H / 2 - 0.5, 1.0])
        assert (p[0] / p[2] + 0.5) / W == pytest.approx(new_x, abs=1e-9)


def test_yaw_then_minus_yaw_returns_the_label():
    rng = np.random.default_rng(1)
    for _ in range(200):
        x = float(rng.uniform(0.05, 0.95))
        psi = float(rng.uniform(-20, 20))
        x1, b1 = yaw_label(x, x_to_bin(x), psi)
        if x1 is None:
            continue
        x2, b2 = yaw_label(x1, b1, -psi)
        assert x2 == pytest.approx(x, abs=1e-12) and b2 == x_to_bin(x)


def test_yaw_then_minus_yaw_restores_the_seen_pixels():
    rng = np.random.default_rng(2)
    img = np.kron(rng.integers(0, 256, (H // 8, W // 8, 3)), np.ones((8, 8, 1))).astype(np.uint8)
    out, _, _, valid = yaw(img, 0.5, 7, 10.0)
    back, _, _, valid2 = yaw(out, 0.5, 7, -10.0)
    ok = valid2 & np.pad(np.ones((H - 16, W - 16), bool), 8)
    both = ok & (back.sum(-1) > 0)
    diff = np.abs(back.astype(int) - img.astype(int))[both]
    assert both.mean() > 0.5 and np.median(diff) <= 2


def test_valid_mask_marks_unseen_pixels():
    img = np.full((H, W, 3), 100, np.uint8)
    out, _, _, valid = yaw(img, 0.5, 7, 20.0)   # turned right: the right edge was never seen
    assert valid[:, 0].all() and not valid[:, -1].any()
    assert (out[~valid] == 0).all() and (out[valid] > 0).all()
    out0, x0, b0, valid0 = yaw(img, 0.5, 7, 0.0)
    assert valid0.all() and x0 == pytest.approx(0.5) and b0 == 7
    np.testing.assert_array_equal(out0, img)


def test_goal_leaving_the_frame_is_unknown_or_edge():
    assert yaw_label(0.05, 1, 30.0) == (None, 0)
    assert yaw_label(0.05, 1, 30.0, out_of_frame="edge") == (None, 1)
    assert yaw_label(0.95, 12, -30.0, out_of_frame="edge") == (None, 12)
    assert yaw_label(0.5, 7, 120.0) == (None, 0)            # behind the camera
    assert yaw_label(None, 0, 10.0) == (None, 0)
    with pytest.raises(ValueError, match="out_of_frame"):
        yaw_label(0.5, 7, 10.0, out_of_frame="clip")


def test_bin_only_labels_move_their_centre():
    x_new, b = yaw_label(None, 7, 10.0)
    assert x_new is None and b == x_to_bin(yaw_x(6.5 / 12, 10.0))


def test_fov_is_the_actions_pinhole():
    k = intrinsics(W, H, 60.0)
    for x in (0.1, 0.5, 0.9):
        heading = math.degrees(math.atan((x * W - 0.5 - k[0, 2]) / k[0, 0]))
        assert heading == pytest.approx(x_to_heading(x, 60.0), abs=1e-9)
    assert heading_to_x(x_to_heading(0.2)) == pytest.approx(0.2)


def test_random_yaw_is_reproducible_and_grayscale_ok():
    img = np.zeros((H, W), np.uint8)
    a = random_yaw(img, 0.5, 7, np.random.default_rng(5))
    b = random_yaw(img, 0.5, 7, np.random.default_rng(5))
    assert a[4] == b[4] and -15 <= a[4] <= 15 and a[0].shape == (H, W)


def test_random_augment_keeps_labels_consistent_with_far_x():
    from crossing_assist.data_tools.augment import random_augment
    rng = np.random.default_rng(9)
    img = np.zeros((H, W, 3), np.uint8)
    mirrored = 0
    for _ in range(100):
        out, x, b, valid = random_augment(img, 0.3, x_to_bin(0.3), rng, p_mirror=0.5, max_yaw_deg=10)
        assert out.shape == img.shape and valid.shape == (H, W)
        assert (b == 0 and x is None) or b == x_to_bin(x)
        mirrored += x is not None and x > 0.5
    assert 25 < mirrored < 75     # p = 0.5; fails by luck with probability < 1e-6
    out, x, b, valid = random_augment(img, 0.3, 4, rng, p_mirror=0.0)
    assert (x, b) == (0.3, 4) and valid.all()


def test_warp_maps_are_the_inverse_homography():
    from crossing_assist.data_tools.augment import _yaw_maps
    for psi in (-25.0, 7.0):
        map_x, map_y, valid = _yaw_maps(W, H, psi, 90.0)
        h_inv = np.linalg.inv(yaw_homography(W, H, psi))
        vs, us = np.nonzero(valid)
        pts = h_inv @ np.stack([us, vs, np.ones_like(us)]).astype(float)
        np.testing.assert_allclose(map_x[vs, us], np.clip(pts[0] / pts[2], 0, W - 1), atol=1e-3)
        np.testing.assert_allclose(map_y[vs, us], np.clip(pts[1] / pts[2], 0, H - 1), atol=1e-3)
