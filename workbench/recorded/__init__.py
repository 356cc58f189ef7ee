"""Readers (and writers) of recorded detections: active-sonar detection lists (:mod:`.sonar`) and passive-radar
range-Doppler candidate lists (:mod:`.pcl`), both validated CSV formats documented in ``docs/recorded-data.md``."""

from .pcl import load_pcl_candidates, write_pcl_candidates
from .pcl import PCLMetadata, pcl_metadata
from .sonar import OwnShip, SonarRecording, load_sonar_csv, load_sonar_recording, write_sonar_csv
from ..textfields import ImplausibleValueWarning

__all__ = ["load_sonar_csv", "load_sonar_recording", "write_sonar_csv", "OwnShip", "SonarRecording",
           "load_pcl_candidates", "write_pcl_candidates", "pcl_metadata", "PCLMetadata", "ImplausibleValueWarning"]
