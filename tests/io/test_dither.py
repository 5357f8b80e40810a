"""Blue-noise dithering of 8-bit output: the mean kept, the bands of a smooth gradient broken up."""

import numpy as np
import pytest

from benchmarks._lib import blue_noise_ratio, radial_power_spectrum
from rtmesh.io.colour import linear_to_srgb, tonemap
from rtmesh.io.images import DITHER_TILE, dither_thresholds, read_image, write_image
from rtmesh.sampling.dither_tile import blue_noise_tile


def written(tmp_path, image, dither, name="out.png", alpha=None):
    """The 8-bit values (0..255, float) of ``image`` written as a PNG, and its display
    values times 255 (what rounding approximates)."""
    path = tmp_path / name
    write_image(path, image, operator="clamp", dither=dither, alpha=alpha)
    pixels, _ = read_image(path)
    display = linear_to_srgb(tonemap(np.asarray(image, np.float32), 0.0, "clamp")).astype(np.float64)
    return np.round(pixels.astype(np.float64) * 255.0), display * 255.0


def block_means(values, block=8):
    """Means of aligned ``block`` x ``block`` blocks of the channel mean, (h / block, w / block)."""
    grey = values.mean(axis=2)
    h, w = grey.shape
    return grey.reshape(h // block, block, w // block, block).mean(axis=(1, 3))


def test_shipped_thresholds_are_what_the_zsobol_sampler_gives():
    assert np.array_equal(dither_thresholds(), blue_noise_tile())


def test_thresholds_are_stratified_blue_noise():
    t = dither_thresholds()
    assert t.shape == (DITHER_TILE, DITHER_TILE)
    # every aligned 4x4 block holds one threshold in each sixteenth of [0, 1)
    cells = np.floor(t * 16).astype(int).reshape(DITHER_TILE // 4, 4, DITHER_TILE // 4, 4).transpose(0, 2, 1, 3)
    assert (np.sort(cells.reshape(-1, 16), axis=1) == np.arange(16)).all()
    assert blue_noise_ratio(radial_power_spectrum(t)[1]) > 2.0


@pytest.mark.parametrize("level", [0.2, 0.5137, 0.9])
def test_dithering_keeps_the_mean_of_a_flat_image(tmp_path, level):
    # a display value between two steps: rounding gives the nearer everywhere (an error of
    # up to half a step in every pixel, the same sign); dithering mixes the two steps in
    # the proportion that keeps the mean
    image = np.full((128, 160, 3), level ** 2.2, np.float32)
    pixels, display = written(tmp_path, image, dither=True)
    nearest, _ = written(tmp_path, image, dither=False, name="nearest.png")
    assert abs(pixels.mean() - display.mean()) <= 0.01
    assert set(np.unique(pixels)) <= {np.floor(display[0, 0, 0]), np.ceil(display[0, 0, 0])}
    assert abs(nearest.mean() - display.mean()) == pytest.approx(np.abs(np.round(display) - display).max(), abs=1e-9)


def test_dithering_breaks_up_the_bands_of_a_smooth_gradient(tmp_path):
    # a dark ramp rising by 4 steps over 256 pixels: rounded, it is 5 flat bands whose
    # 8x8 block means miss the ramp by up to half a step; dithered, every block mean
    # follows it
    h, w = 64, 256
    display = np.tile(0.1 + (np.arange(w) + 0.5) / w * 4.0 / 255.0, (h, 1))
    image = np.repeat(((display + 0.055) / 1.055) ** 2.4, 3).reshape(h, w, 3)
    dithered, target = written(tmp_path, image, dither=True)
    nearest, _ = written(tmp_path, image, dither=False, name="nearest.png")
    assert np.abs(block_means(nearest) - block_means(target)).max() > 0.4
    assert np.abs(block_means(dithered) - block_means(target)).max() < 0.1
    assert abs(dithered.mean() - target.mean()) < 0.01
    # and the error is blue noise: its power in the high frequencies
    error = (dithered - target).mean(axis=2)
    assert blue_noise_ratio(radial_power_spectrum(error)[1]) > 2.0


def test_alpha_and_exr_are_not_dithered(tmp_path):
    image = np.full((16, 16, 3), 0.3, np.float32)
    alpha = np.full((16, 16), 0.5, np.float32)
    write_image(tmp_path / "a.png", image * alpha[:, :, None], alpha=alpha, dither=True)
    rgba, _ = read_image(tmp_path / "a.png")
    assert np.unique(np.round(rgba[:, :, 3] * 255)).tolist() == [128.0]
    write_image(tmp_path / "a.exr", image, dither=True)
    linear, _ = read_image(tmp_path / "a.exr")
    np.testing.assert_array_equal(linear[:, :, :3], image)


def test_a_render_result_writes_itself_as_its_settings_say(tmp_path):
    """``RenderResult.write``: the settings' dither (a scene file's ``[render] dither``, or an
    override of ``rtmesh.render``), exposure and tone map, as ``write_image`` with them."""
    import rtmesh
    from scenes import settings, sphere_on_floor_scene

    result = rtmesh.render(sphere_on_floor_scene(subdivisions=1), settings(width=32, height=24), dither=True,
                           exposure=0.5, tonemap="agx")
    assert result.settings.dither
    result.write(tmp_path / "result.png")
    for dither in (True, False):
        write_image(tmp_path / f"{dither}.png", result.image, exposure=0.5, operator="agx", dither=dither)
    written, dithered, rounded = (read_image(tmp_path / f"{name}.png")[0] for name in ("result", True, False))
    assert np.array_equal(written, dithered) and not np.array_equal(written, rounded)
    result.write(tmp_path / "result.exr")  # the settings in the header, as the command writes them
    import OpenImageIO as oiio

    header = oiio.ImageInput.open(str(tmp_path / "result.exr")).spec()
    assert header.getattribute("rtmesh:spp") == 1 and header.getattribute("rtmesh:sampler") == "regular"
