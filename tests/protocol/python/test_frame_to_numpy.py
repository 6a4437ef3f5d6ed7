"""Frame.to_numpy: PNG and JPEG frames as height x width x 4 uint8 arrays, the refusals, and
the error that names a missing numpy or Pillow.

The PNGs are written here with the standard library (zlib), so their pixels are known exactly
without Pillow's encoder. Needs Debian's python3-numpy and python3-pil (deploy/install.sh);
the tests that decode skip, saying which is absent, where they are not installed."""

import io
import struct
import sys
import unittest
import zlib
from unittest import mock

import volcast as vc

try:
    import numpy
except ImportError:
    numpy = None
try:
    import PIL.Image
except ImportError:
    PIL = None

NEEDS = "numpy and Pillow are not both installed (Debian: python3-numpy python3-pil, in deploy/install.sh)"


def png(width, height, channels, pixel):
    """An 8-bit PNG (channels 3: RGB, 4: RGBA) whose pixel (x, y) is pixel(x, y)."""
    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    color_type = {3: 2, 4: 6}[channels]
    rows = b"".join(b"\x00" + bytes(v for x in range(width) for v in pixel(x, y)) for y in range(height))
    return (b"\x89PNG\r\n\x1a\n"
            + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, color_type, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b""))


def frame(image, width, height, codec="png", view=None):
    header = {"seq": 7, "level": 0, "width": width, "height": height, "codec": codec,
              "render_ms": 1.0, "encode_ms": 0.5, "final": True}
    if view is not None:
        header["view_width"], header["view_height"] = view
    return vc.decode_frame(vc.encode_frame(header, image))


def rgba(x, y):
    # Every channel different and position-dependent, so a transposed or flipped decode fails.
    return (x * 40, y * 60, (x * 7 + y * 13) % 256, 255 - x - y)


@unittest.skipUnless(numpy is not None and PIL is not None, NEEDS)
class Decode(unittest.TestCase):
    def test_png_rgba_decodes_to_its_exact_pixels(self):
        width, height = 5, 3
        pixels = frame(png(width, height, 4, rgba), width, height).to_numpy()
        self.assertEqual(pixels.shape, (height, width, 4), "rows x columns x RGBA")
        self.assertEqual(pixels.dtype, numpy.uint8)
        want = numpy.array([[rgba(x, y) for x in range(width)] for y in range(height)], numpy.uint8)
        numpy.testing.assert_array_equal(pixels, want, "PNG is lossless: every value must match")

    def test_png_rgb_gets_opaque_alpha(self):
        pixels = frame(png(4, 2, 3, lambda x, y: rgba(x, y)[:3]), 4, 2).to_numpy()
        self.assertEqual(pixels.shape, (2, 4, 4))
        self.assertTrue((pixels[:, :, 3] == 255).all(), f"alpha of an RGB PNG: {pixels[:, :, 3]}")

    def test_jpeg_decodes_within_quantization_error(self):
        # Two flat 8x8 blocks: JPEG then keeps only each block's DC term, which quality 95
        # quantizes to within a few levels (libjpeg's tables; measured 0-1 here), so 4 of 255.
        width, height = 16, 8
        colors = [(200, 40, 90), (30, 160, 220)]
        picture = PIL.Image.new("RGB", (width, height))
        picture.putdata([colors[x // 8] for y in range(height) for x in range(width)])
        encoded = io.BytesIO()
        picture.save(encoded, "JPEG", quality=95, subsampling=0)
        pixels = frame(encoded.getvalue(), width, height, codec="jpeg").to_numpy()
        self.assertEqual(pixels.shape, (height, width, 4))
        want = numpy.array([[colors[x // 8] for x in range(width)] for y in range(height)], numpy.int16)
        worst = int(numpy.abs(pixels[:, :, :3].astype(numpy.int16) - want).max())
        self.assertLessEqual(worst, 4, f"JPEG decode differs by {worst} levels from the flat colours")
        self.assertTrue((pixels[:, :, 3] == 255).all(), "JPEG has no alpha: 255 everywhere")

    def test_image_of_another_size_than_the_header_is_refused(self):
        bad = frame(png(5, 3, 4, rgba), 6, 3)
        with self.assertRaisesRegex(vc.FrameError, r"frame 7: the image is 5x3 but the header says 6x3"):
            bad.to_numpy()

    def test_a_frame_smaller_than_its_view_is_scaled_up_to_it(self):
        # A 2x1 image of a 4x2 view: bilinear between pixel centres, clamped at the edges, as
        # the browser's canvas draws it. Along x the centres of the view's pixels fall at
        # -0.25, 0.25, 0.75, 1.25 of the image's: 0, 1/4, 3/4 and 1 of the way from 0 to 200.
        picture = frame(png(2, 1, 4, lambda x, y: (200 * x, 0, 0, 255)), 2, 1, view=(4, 2))
        self.assertEqual((picture.view_width, picture.view_height), (4, 2))
        pixels = picture.to_numpy()
        self.assertEqual(pixels.shape, (2, 4, 4), "view_height x view_width x RGBA")
        numpy.testing.assert_allclose(pixels[:, :, 0], [[0, 50, 150, 200]] * 2, atol=1,
                                      err_msg="Pillow's bilinear, rounded: within one level")
        self.assertEqual(picture.to_numpy(at_view_size=False).shape, (1, 2, 4), "as sent")

    def test_a_view_too_large_to_allocate_is_refused_naming_it(self):
        # 65536 x 65536 passes the header's checks; scaled up it would be 16 GiB of RGBA.
        huge = frame(png(2, 1, 4, rgba), 2, 1, view=(65536, 65536))
        with self.assertRaisesRegex(vc.FrameError, r"frame 7: a view of 65536x65536 is over"):
            huge.to_numpy()
        self.assertEqual(huge.to_numpy(at_view_size=False).shape, (1, 2, 4), "as sent it still decodes")

    def test_a_frame_without_a_view_size_is_shown_at_its_own(self):
        picture = frame(png(3, 2, 4, rgba), 3, 2)
        self.assertEqual((picture.view_width, picture.view_height), (3, 2))
        self.assertEqual(picture.to_numpy().shape, (2, 3, 4))

    def test_bytes_that_are_not_the_codec_are_refused(self):
        with self.assertRaisesRegex(vc.FrameError, "frame 7: the png image does not decode"):
            frame(b"not a png at all", 2, 2).to_numpy()
        # A PNG sent as a JPEG frame: the header's codec is what is decoded, not a guess.
        with self.assertRaisesRegex(vc.FrameError, "frame 7: the jpeg image does not decode"):
            frame(png(2, 2, 4, rgba), 2, 2, codec="jpeg").to_numpy()


class ViewSize(unittest.TestCase):
    def test_a_view_smaller_than_the_image_is_refused(self):
        with self.assertRaisesRegex(vc.FrameError, r"view_width: must be an integer in \[3, 65536\], got 2"):
            frame(b"", 3, 2, view=(2, 2))
        with self.assertRaisesRegex(vc.FrameError, r"view_height: must be an integer in \[2, 65536\], got 70000"):
            frame(b"", 3, 2, view=(3, 70000))
        with self.assertRaisesRegex(vc.FrameError, r"view_width: must be an integer, got str"):
            frame(b"", 3, 2, view=("wide", 2))


class MissingPackages(unittest.TestCase):
    # sys.modules[name] = None makes `import name` raise ImportError: the package's absence,
    # whether or not it is installed here.

    def test_without_numpy_the_error_names_numpy(self):
        with mock.patch.dict(sys.modules, {"numpy": None}):
            with self.assertRaises(vc.MissingDependencyError) as caught:
                frame(png(2, 2, 4, rgba), 2, 2).to_numpy()
        self.assertIsInstance(caught.exception, ImportError)
        self.assertIn("'numpy'", str(caught.exception))
        self.assertIn("python3-numpy", str(caught.exception))

    @unittest.skipUnless(numpy is not None, "numpy is not installed (Debian: python3-numpy, in "
                         "deploy/install.sh); the Pillow check runs after numpy's")
    def test_without_pillow_the_error_names_pillow(self):
        with mock.patch.dict(sys.modules, {"PIL": None, "PIL.Image": None}):
            with self.assertRaises(vc.MissingDependencyError) as caught:
                frame(png(2, 2, 4, rgba), 2, 2).to_numpy()
        self.assertIn("'Pillow'", str(caught.exception))
        self.assertIn("python3-pil", str(caught.exception))
        self.assertIn("decoding png", str(caught.exception))

    def test_the_rest_of_the_package_works_without_numpy(self):
        with mock.patch.dict(sys.modules, {"numpy": None, "PIL": None, "PIL.Image": None}):
            decoded = frame(png(2, 2, 4, rgba), 2, 2)
            self.assertEqual((decoded.width, decoded.height, decoded.codec), (2, 2, "png"))
            self.assertEqual(vc.dumps(vc.still()), '{"type":"still"}')


if __name__ == "__main__":
    unittest.main()
