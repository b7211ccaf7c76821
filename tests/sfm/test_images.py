"""Image preparation: EXIF orientation maps, downscaling, unreadable files, focal prior."""

from __future__ import annotations

import numpy as np
import piexif
import pytest
from PIL import Image

from kitegully import InputError
from kitegully.sfm.images import (
    _apply_orientation,
    display_to_stored,
    exif_orientation,
    focal_length_px,
    list_images,
    prepare_images,
    read_image,
    stored_to_display,
    to_sfm_pixels,
)


def _jpeg(path, w=64, h=48, orientation=None, when=b"2012:08:19 12:00:00", seed=0):
    rng = np.random.default_rng(seed)
    arr = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
    exif = {"0th": {}, "Exif": {piexif.ExifIFD.DateTimeOriginal: when, piexif.ExifIFD.FocalLength: (5000, 1000),
                               piexif.ExifIFD.FocalPlaneXResolution: (w * 1000, 259), piexif.ExifIFD.FocalPlaneResolutionUnit: 2}}
    if orientation:
        exif["0th"][piexif.ImageIFD.Orientation] = orientation
    Image.fromarray(arr).save(path, quality=98, exif=piexif.dump(exif))
    return path


@pytest.mark.parametrize("orientation", range(1, 9))
def test_pixel_maps_agree_with_the_pil_transposes(orientation):
    # a stored image with one marked pixel: where does it show up on display?
    W, H = 7, 5
    arr = np.zeros((H, W), np.uint8)
    sx, sy = 5, 1
    arr[sy, sx] = 255
    disp = np.asarray(_apply_orientation(Image.fromarray(arr), orientation))
    dy, dx = np.argwhere(disp == 255)[0]
    # pixel centres: continuous coordinates (x + 0.5, y + 0.5)
    got = stored_to_display(np.array([[sx + 0.5, sy + 0.5]]), orientation, W, H)[0]
    np.testing.assert_allclose(got, [dx + 0.5, dy + 0.5])
    back = display_to_stored(got[None], orientation, W, H)[0]
    np.testing.assert_allclose(back, [sx + 0.5, sy + 0.5])


def test_prepare_keeps_capture_order_stored_frame_and_scale(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    _jpeg(src / "b.jpg", orientation=8, when=b"2012:08:19 12:00:01")
    _jpeg(src / "a.jpg", orientation=None, when=b"2012:08:19 12:00:05")
    infos = prepare_images(list_images(src), tmp_path / "out", max_image_size=32, frame="stored")
    assert [i.name for i in infos] == ["b.jpg", "a.jpg"]  # capture time, not name
    assert [i.orientation for i in infos] == [8, 1]
    assert all((i.sfm_width, i.sfm_height) == (32, 24) for i in infos)  # one sensor shape
    assert infos[0].scale == pytest.approx(0.5)
    # focal 5 mm at 64 px per 259/1000 inch ... = 5 * 64000/259 / 25.4 px, halved
    assert infos[0].focal_px == pytest.approx(5 * 64000 / 259 / 25.4 * 0.5)
    assert Image.open(tmp_path / "out" / infos[0].sfm_name).size == (32, 24)


def test_display_frame_turns_tagged_images_and_maps_gcp_pixels(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    _jpeg(src / "r.jpg", orientation=6, when=b"2012:08:19 12:00:00")
    _jpeg(src / "s.jpg", orientation=1, when=b"2012:08:19 12:00:09")
    infos = prepare_images(list_images(src), tmp_path / "out", max_image_size=0, frame="display")
    assert (infos[0].sfm_width, infos[0].sfm_height) == (48, 64)
    assert (infos[1].sfm_width, infos[1].sfm_height) == (64, 48)
    stored = read_image(src / "r.jpg", "stored")
    disp = read_image(src / "r.jpg", "display")
    assert disp.shape == (64, 48, 3) and exif_orientation(src / "r.jpg") == 6
    # a pixel measured on the display image maps to the same content in the stored frame
    xy_disp = np.array([[10.5, 40.5]])
    xy_st = to_sfm_pixels(xy_disp, infos[0], "display", "stored")
    np.testing.assert_array_equal(stored[int(xy_st[0, 1]), int(xy_st[0, 0])], disp[40, 10])
    # measured at half scale on the stored frame -> display frame at full scale
    np.testing.assert_allclose(to_sfm_pixels(xy_st / 2, infos[0], "stored", "display", 0.5), xy_disp)


def test_unreadable_and_truncated_images_are_listed_in_one_error(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    _jpeg(src / "good1.jpg")
    _jpeg(src / "good2.jpg")
    (src / "junk.jpg").write_bytes(b"not an image")
    full = _jpeg(src / "cut.jpg", w=256, h=256).read_bytes()
    (src / "cut.jpg").write_bytes(full[: len(full) // 2])
    with pytest.raises(InputError, match="unreadable or truncated images") as err:
        prepare_images(list_images(src), tmp_path / "out", 0)
    assert "junk.jpg" in str(err.value) and "cut.jpg" in str(err.value)
    infos = prepare_images(list_images(src), tmp_path / "out2", 0, skip_unreadable=True)
    assert sorted(i.name for i in infos) == ["good1.jpg", "good2.jpg"]


def test_empty_folder_and_missing_focal(tmp_path):
    with pytest.raises(InputError, match="no JPEG"):
        list_images(tmp_path)
    assert np.isnan(focal_length_px({"Exif": {}}, 100, 50))
    assert focal_length_px({"Exif": {piexif.ExifIFD.FocalLengthIn35mmFilm: 36}}, 100, 50) == pytest.approx(100)
