"""find_studies and DICOMweb/upload volume names in the Python client, offline: the message
it sends, the typed Study/Series it makes of a `studies` answer, the ServerError of an
`error` answer, and `retrieving` progress reaching open_volume's callback. The Client talks
to a stand-in socket (test_client.FakeSocket); the live server's side is in ../python_live."""

import asyncio
import datetime
import json
import unittest

import volcast as vc
from test_client import FakeSocket

STUDY = "1.2.826.0.1.3680043.8.498.1"
SERIES_CT = "1.2.826.0.1.3680043.8.498.1.1"
SERIES_SEG = "1.2.826.0.1.3680043.8.498.1.2"

STUDIES_ANSWER = {
    "type": "studies", "id": 1, "source": "orthanc",
    "studies": [{
        "study_uid": STUDY, "patient_name": "Doe^Jane", "patient_id": "P-0042",
        "study_date": "20240315", "description": "CT chest", "accession_number": "A123",
        "modalities": ["CT", "SEG"],
        "series": [
            {"series_uid": SERIES_CT, "modality": "CT", "description": "axial 1 mm", "instances": 300,
             "volume": f"dicomweb:orthanc/{STUDY}/{SERIES_CT}"},
            # Fields a newer server adds are ignored; fields left out take empty values.
            {"series_uid": SERIES_SEG, "modality": "SEG", "instances": 1,
             "volume": f"dicomweb:orthanc/{STUDY}/{SERIES_SEG}", "body_part": "CHEST"},
        ],
        "referring_physician": "ignored",
    }],
}


def run(coroutine):
    return asyncio.run(asyncio.wait_for(coroutine, 5))


class FindStudiesMessage(unittest.TestCase):
    def test_filters_given_are_sent_and_the_others_left_out(self):
        self.assertEqual(vc.find_studies("orthanc"),
                         {"type": "find_studies", "source": "orthanc", "filters": {}, "limit": 100})
        self.assertEqual(
            vc.find_studies("orthanc", patient_name="Doe^J*", patient_id="P-0042", study_date="20240101-20241231",
                            modality="CT", accession_number="A123", limit=5, id=7),
            {"type": "find_studies", "id": 7, "source": "orthanc", "limit": 5,
             "filters": {"patient_name": "Doe^J*", "patient_id": "P-0042", "study_date": "20240101-20241231",
                         "modality": "CT", "accession_number": "A123"}})

    def test_study_dates_from_dates_and_ranges(self):
        def date_of(value):
            return vc.find_studies("s", study_date=value)["filters"]["study_date"]
        self.assertEqual(date_of(datetime.date(2024, 3, 5)), "20240305")
        self.assertEqual(date_of((datetime.date(2024, 1, 1), "20240630")), "20240101-20240630")
        self.assertEqual(date_of(("20240101", None)), "20240101-")   # from that day on
        self.assertEqual(date_of((None, datetime.date(2023, 12, 31))), "-20231231")
        with self.assertRaisesRegex(ValueError, r"\(first, last\) pair"):
            date_of(("20240101",))
        with self.assertRaisesRegex(TypeError, "study_date must be a 'YYYYMMDD' string or a datetime.date"):
            date_of(20240101)

    def test_bad_arguments_are_refused_before_sending(self):
        for limit in (0, 1001, True, 2.5):
            with self.assertRaisesRegex(ValueError, "limit must be an integer in 1..1000", msg=repr(limit)):
                vc.find_studies("s", limit=limit)
        with self.assertRaisesRegex(ValueError, "source must be a non-empty string"):
            vc.find_studies("")
        with self.assertRaisesRegex(TypeError, "patient_id must be a string, got int"):
            vc.find_studies("s", patient_id=42)


class FindStudiesClient(unittest.TestCase):
    def test_a_studies_answer_becomes_typed_studies(self):
        async def scenario():
            socket = FakeSocket([json.dumps(STUDIES_ANSWER)])
            studies = await vc.Client(socket).find_studies("orthanc", patient_name="Doe*", modality="CT")
            self.assertEqual(socket.sent, [{"type": "find_studies", "id": 1, "source": "orthanc", "limit": 100,
                                            "filters": {"patient_name": "Doe*", "modality": "CT"}}])
            return studies
        studies = run(scenario())
        self.assertEqual(studies, [vc.Study(
            study_uid=STUDY, patient_name="Doe^Jane", patient_id="P-0042", study_date="20240315",
            description="CT chest", accession_number="A123", modalities=["CT", "SEG"],
            series=[vc.Series(series_uid=SERIES_CT, modality="CT", description="axial 1 mm", instances=300,
                              volume=f"dicomweb:orthanc/{STUDY}/{SERIES_CT}"),
                    vc.Series(series_uid=SERIES_SEG, modality="SEG", description="", instances=1,
                              volume=f"dicomweb:orthanc/{STUDY}/{SERIES_SEG}")])])

    def test_no_studies_is_an_empty_list(self):
        answer = {"type": "studies", "id": 1, "source": "orthanc", "studies": []}
        self.assertEqual(run(vc.Client(FakeSocket([json.dumps(answer)])).find_studies("orthanc")), [])

    def test_an_error_answer_raises_server_error(self):
        error = {"type": "error", "id": 1, "code": "source_failed", "request_type": "find_studies",
                 "message": "DICOMweb source orthanc: HTTP 401 from http://127.0.0.1:8042/dicom-web/studies"}
        with self.assertRaises(vc.ServerError) as caught:
            run(vc.Client(FakeSocket([json.dumps(error)])).find_studies("orthanc"))
        self.assertEqual(caught.exception.code, "source_failed")
        self.assertIn("HTTP 401", caught.exception.message)
        self.assertIn("source_failed", vc.ERROR_CODES)

    def test_a_malformed_studies_answer_names_the_field(self):
        cases = [
            ({"studies": [{"study_uid": STUDY, "series": [{"series_uid": "1", "instances": "300"}]}]},
             r"studies\[0\].series\[0\].instances: must be an integer, got str"),
            ({"studies": [{"study_uid": 5}]}, r"studies\[0\].study_uid: must be a string"),
            ({"studies": [{"modalities": ["CT", 3]}]}, r"studies\[0\].modalities\[1\]: must be a string"),
            ({"studies": {"a": 1}}, "message.studies: must be an array"),
            ({"studies": ["x"]}, r"studies\[0\]: must be a JSON object"),
        ]
        for fields, message in cases:
            with self.subTest(message=message):
                answer = dict({"type": "studies", "id": 1, "source": "orthanc"}, **fields)
                with self.assertRaisesRegex(vc.MessageError, message):
                    run(vc.Client(FakeSocket([json.dumps(answer)])).find_studies("orthanc"))


class OpenProviderVolumes(unittest.TestCase):
    def test_dicomweb_names_are_sent_as_they_are_and_retrieving_progress_is_passed_on(self):
        name = f"dicomweb:orthanc/{STUDY}/{SERIES_CT}"
        progress = [
            {"type": "progress", "id": 1, "volume": name, "stage": "retrieving", "instances": [0, 300], "bytes": 0},
            {"type": "progress", "id": 1, "volume": name, "stage": "retrieving", "instances": [150, 300],
             "bytes": 78643200},
            {"type": "progress", "id": 1, "volume": name, "stage": "retrieving"},   # neither is required
            {"type": "progress", "id": 1, "volume": name, "stage": "loading", "fraction": 0.5},
        ]
        state = {"type": "state", "id": 1, "volume": {"name": name, "dims": [512, 512, 300]}, "scene": {},
                 "quality_policy": {"mode": "automatic"}, "interacting": False}

        async def scenario():
            socket = FakeSocket([json.dumps(m) for m in progress + [state]])
            seen = []
            got = await vc.Client(socket).open_volume(name, on_progress=seen.append)
            self.assertEqual(socket.sent, [{"type": "open_volume", "id": 1, "name": name}])
            return got, seen
        got, seen = run(scenario())
        self.assertEqual(got["volume"]["name"], name)
        self.assertEqual(seen, progress)
        self.assertEqual(vc.open_volume("upload:0123456789abcdef0123456789abcdef"),
                         {"type": "open_volume", "name": "upload:0123456789abcdef0123456789abcdef"})


if __name__ == "__main__":
    unittest.main()
