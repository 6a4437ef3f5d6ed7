"""The `studies` answer to `find_studies` as typed objects: Study and its Series. Standard
library only. Lenient out (protocol/README.md): fields the client does not know are ignored,
fields left out take empty values; a field of the wrong kind is a MessageError naming it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, List

from .messages import MessageError


def _text(obj: Dict[str, Any], key: str, where: str) -> str:
    value = obj.get(key)
    if value is None:
        return ""
    if not isinstance(value, str):
        raise MessageError(f"{where}.{key}: must be a string, got {type(value).__name__}")
    return value


def _list(obj: Dict[str, Any], key: str, where: str) -> List[Any]:
    value = obj.get(key)
    if value is None:
        return []
    if not isinstance(value, list):
        raise MessageError(f"{where}.{key}: must be an array, got {type(value).__name__}")
    return value


def _object(value: Any, where: str) -> Dict[str, Any]:
    if not isinstance(value, dict):
        raise MessageError(f"{where}: must be a JSON object, got {type(value).__name__}")
    return value


@dataclass
class Series:
    """One series of a study. `volume` is the name open_volume takes
    (`dicomweb:SOURCE/STUDY_UID/SERIES_UID`); `instances` is what the PACS reported (0 when
    it did not say)."""

    series_uid: str
    modality: str = ""
    description: str = ""
    instances: int = 0
    volume: str = ""

    @classmethod
    def from_json(cls, obj: Any, where: str = "series") -> Series:
        obj = _object(obj, where)
        instances = obj.get("instances")
        if instances is None:
            instances = 0
        elif isinstance(instances, bool) or not isinstance(instances, int):
            raise MessageError(f"{where}.instances: must be an integer, got {type(instances).__name__}")
        return cls(series_uid=_text(obj, "series_uid", where), modality=_text(obj, "modality", where),
                   description=_text(obj, "description", where), instances=instances,
                   volume=_text(obj, "volume", where))


@dataclass
class Study:
    """One study a `find_studies` search found. study_date is DICOM's "YYYYMMDD" (as the
    PACS sent it); patient_name is DICOM's `Family^Given` form."""

    study_uid: str
    patient_name: str = ""
    patient_id: str = ""
    study_date: str = ""
    description: str = ""
    accession_number: str = ""
    modalities: List[str] = field(default_factory=list)
    series: List[Series] = field(default_factory=list)

    @classmethod
    def from_json(cls, obj: Any, where: str = "study") -> Study:
        obj = _object(obj, where)
        modalities = _list(obj, "modalities", where)
        for i, m in enumerate(modalities):
            if not isinstance(m, str):
                raise MessageError(f"{where}.modalities[{i}]: must be a string, got {type(m).__name__}")
        series = [Series.from_json(s, f"{where}.series[{i}]")
                  for i, s in enumerate(_list(obj, "series", where))]
        return cls(study_uid=_text(obj, "study_uid", where), patient_name=_text(obj, "patient_name", where),
                   patient_id=_text(obj, "patient_id", where), study_date=_text(obj, "study_date", where),
                   description=_text(obj, "description", where),
                   accession_number=_text(obj, "accession_number", where),
                   modalities=list(modalities), series=series)


def parse_studies(message: Dict[str, Any]) -> List[Study]:
    """The studies of a `studies` message (a dict, as parse_server_message gives it)."""
    if message.get("type") != "studies":
        raise MessageError(f"expected a studies message, got {message.get('type')!r}")
    return [Study.from_json(s, f"studies[{i}]") for i, s in enumerate(_list(message, "studies", "message"))]
