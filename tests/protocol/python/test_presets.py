"""volcast.preset: the presets a server sends with a volume (protocol/README.md, volume object
`modality`), by name or the default, and a clear error naming what there is."""

import unittest

import volcast as vc

VOLUME = {
    "name": "cranium_ct.nhdr", "loaded": True, "orientation_known": False,
    "modality": {
        "name": "CT", "source": "inferred", "reason": "air near -1000", "default_preset": "ct.bone",
        "presets": [
            {"name": "ct.bone", "label": "CT bone", "window": 2000, "level": 400, "shading": True,
             "points": [[-600, 0, 0, 0, 0], [1400, 1, 1, 1, 0.9]]},
            {"name": "ct.lung", "label": "CT lung", "window": 1500, "level": -600, "shading": True,
             "points": [[-1350, 0, 0, 0, 0], [150, 1, 1, 1, 0]]},
        ],
    },
}


class PresetTest(unittest.TestCase):
    def test_default_and_named(self) -> None:
        self.assertEqual(vc.preset(VOLUME)["name"], "ct.bone")
        self.assertEqual(vc.preset(VOLUME, "ct.lung")["level"], -600)
        message = vc.transfer_function({"points": vc.preset(VOLUME)["points"]})
        self.assertEqual(message["transfer_function"]["points"][0], [-600, 0, 0, 0, 0])

    def test_unknown_names_what_there_is(self) -> None:
        with self.assertRaises(KeyError) as e:
            vc.preset(VOLUME, "mr.t1_brain")
        self.assertIn("ct.bone, ct.lung", str(e.exception))
        with self.assertRaises(KeyError) as e:
            vc.preset({"name": "builtin:demo"})
        self.assertIn("sent no presets", str(e.exception))


if __name__ == "__main__":
    unittest.main()
