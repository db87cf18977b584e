"""The decoder node's parameters: one table per settings dataclass, declared in one loop each.

The node's own settings (inputs, files, outputs, threads, warnings) are
:class:`DecoderNodeSettings`, the sensor file's overrides :class:`ElastomerOverrides`; the
library's settings (decoding, stereo, outliers, carry, transfer, rescue, artwork fit,
extraction, touch, contact, diagnostics) bring their tables from their own modules.
:data:`DECODER_TABLES` lists them all with the name prefix and the words that open each
description: the node declares from it, and a test compares every declared parameter with
its table.  No rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

from tactile_sl_common.settings import SettingsTable, frame_prefix_check
from tactile_sl_decoder.classify.carry import CARRY_SETTINGS
from tactile_sl_decoder.decode.codewords import DECODE_SETTINGS
from tactile_sl_decoder.extract.extraction import EXTRACTION_SETTINGS
from tactile_sl_decoder.nodes.diagnostics import DIAGNOSTIC_SETTINGS
from tactile_sl_decoder.stereo.artwork_fit import ARTWORK_FIT_SETTINGS
from tactile_sl_decoder.stereo.outliers import OUTLIER_SETTINGS
from tactile_sl_decoder.stereo.rescue import RESCUE_SETTINGS
from tactile_sl_decoder.stereo.stereo import STEREO_SETTINGS
from tactile_sl_decoder.stereo.transfer import TRANSFER_SETTINGS
from tactile_sl_decoder.touch.contact import CONTACT_SETTINGS
from tactile_sl_decoder.touch.sensor import SensorConfig
from tactile_sl_decoder.touch.stage import TOUCH_SETTINGS
from tactile_sl_decoder.touch.weights import WEIGHT_SETTINGS

INPUTS = ("images", "symbols")


def _input_check(value: str) -> str | None:
    return None if value in INPUTS else "must be 'images' or 'symbols'"


@dataclass
class DecoderNodeSettings:
    """The node's own settings: what it reads, what it publishes, its threads and warnings."""

    input: str = "images"
    """'images': run extraction + classification in-process on left/right image_raw (lowest
    latency); 'symbols': consume left/right symbols from the stage nodes."""
    pattern_file: str = ""
    """Pattern YAML (contract format); empty = the pattern the package ships."""
    allow_invalid_pattern: bool = False
    """Use a pattern file that breaks its own min_hamming / window uniqueness (experiments
    only: cells may be wrong)."""
    classifier_weights: str = ""
    """Classifier weights from `tactile-sl train`; empty = the shipped ones. Their class count
    must equal the pattern's symbols."""
    classifier_threshold: float = -1.0
    """Confidence below which a glyph's label is unknown (255), in [0, 1]; < 0 = the value
    stored with the weights (input=images, or unlabelled symbols)."""
    frame_prefix: str = ""
    """Prepended to every frame id this node publishes (e.g. 'left_hand_'), so several sensors
    on one robot have distinct frames; empty = none. Here: the pad frame of the touch outputs
    (the cloud keeps the left CameraInfo's frame, which the camera driver prefixes) and the
    diagnostics' hardware_id."""
    sync_slop: float = 0.0
    """Seconds by which left/right stamps may differ when no exactly equal stamp exists (0 =
    exact stamps only, the contract's stereo convention)."""
    input_depth: int = 1
    """QoS history depth of the input subscriptions (sensor data, best effort). Small keeps
    latency low when the node falls behind: older frames are replaced by newer ones in the
    middleware instead of queueing up (1: only the newest frame waits)."""
    queue_size: int = 5
    """Unpaired messages kept per side while waiting for the stereo partner."""
    max_age: float = 0.5
    """Seconds after which an unpaired message is dropped as stale."""
    publish_symbols: bool = True
    """Publish left/right symbols_decoded (labelled + decoded SymbolArrays)."""
    publish_patches: bool = False
    """Include the glyph patches in symbols_decoded (larger messages)."""
    publish_empty: bool = True
    """Publish a cloud with no point for frames that decoded nothing."""
    camera_processes: bool = True
    """Extract and classify the right camera's images in a worker process while this
    process does the left camera's (input=images): the two images on two cores side by
    side, without sharing Python's interpreter lock; this process then decodes and runs the
    touch stage. false = both in this process (see threads). The same results either way."""
    threads: int = 2
    """Without camera_processes: worker threads for the two images of a frame (2 extracts and
    classifies them concurrently, 1 = sequential)."""
    cpu_threads: int = 1
    """Intra-op threads of OpenCV and BLAS in this process (0 = library defaults); 1 avoids
    oversubscription on small shared machines."""
    warn_period: float = 5.0
    """Seconds between two warnings of the same kind (throttling)."""
    diagnostic_period: float = 1.0
    """Seconds between two DiagnosticArrays on /diagnostics (docs/diagnostics.md)."""
    touch: bool = True
    """Publish field, wrench, contact, depth, slip and pad_pose (needs an untouched pad at
    start: the reference)."""
    sensor_file: str = ""
    """Sensor YAML (elastomer, pad frame); empty = the shipped one."""
    pad_frame: str = ""
    """Frame id of the touch outputs; empty = the sensor file's."""


DECODER_NODE_SETTINGS = SettingsTable(
    DecoderNodeSettings,
    ranges={"classifier_threshold": (-1.0, 1.0), "sync_slop": (0.0, 10.0),
            "input_depth": (1, 1000), "queue_size": (1, 1000), "max_age": (0.001, 3600.0),
            "threads": (1, 2), "cpu_threads": (0, 256), "warn_period": (0.0, 3600.0),
            "diagnostic_period": (0.1, 60.0)},
    read_only=("input", "pattern_file", "allow_invalid_pattern", "classifier_weights",
               "frame_prefix", "input_depth", "publish_symbols", "camera_processes", "threads",
               "cpu_threads",
               "diagnostic_period", "touch", "sensor_file", "pad_frame"),
    checks={"input": _input_check, "frame_prefix": frame_prefix_check})


@dataclass
class ElastomerOverrides:
    """Values that override the sensor file's elastomer (< 0: the file's value)."""

    youngs_modulus: float = -1.0
    """Pa; overrides the sensor file (< 0 = the file's value)."""
    poisson_ratio: float = -1.0
    """Overrides the sensor file (< 0 = the file's value), 0..0.5."""
    thickness: float = -1.0
    """m, layer bonded to a rigid window, 0 = half-space; overrides the sensor file (< 0 =
    the file's value)."""

    def apply_to(self, sensor: SensorConfig, pad_frame: str = "") -> SensorConfig:
        """``sensor`` with these overrides (and ``pad_frame`` unless empty)."""
        def given(value: float) -> float | None:
            return None if float(value) < 0 else float(value)

        return sensor.with_overrides(given(self.youngs_modulus), given(self.poisson_ratio),
                                     given(self.thickness), pad_frame or None)


ELASTOMER_OVERRIDES = SettingsTable(
    ElastomerOverrides, ranges={"youngs_modulus": (-1.0, 1e12), "poisson_ratio": (-1.0, 0.5),
                                "thickness": (-1.0, 1.0)},
    read_only=("youngs_modulus", "poisson_ratio", "thickness"))


class Declared(NamedTuple):
    """One table as the decoder declares it: settings object, name prefix, description lead."""

    name: str          # the settings object it fills (see DecoderNode._declare_settings)
    table: SettingsTable
    prefix: str = ""
    what: str = ""


DECODER_TABLES: tuple[Declared, ...] = (
    Declared("node", DECODER_NODE_SETTINGS),
    Declared("decode", DECODE_SETTINGS),
    Declared("stereo", STEREO_SETTINGS),
    Declared("outliers", OUTLIER_SETTINGS, "outliers.",
             "Surface outlier test (docs/robustness.md): "),
    Declared("carry", CARRY_SETTINGS, "carry.",
             "Labels carried from the previous frame (input=images; docs/decoder.md, "
             "'Temporal coherence'): "),
    Declared("transfer", TRANSFER_SETTINGS, "transfer.",
             "Cells across the stereo pair (docs/robustness.md, 'Cells across the stereo "
             "pair'): "),
    Declared("rescue", RESCUE_SETTINGS, "rescue.",
             "Glyphs one camera did not detect (input=images; docs/robustness.md, 'Glyphs "
             "one camera did not detect'): "),
    Declared("artwork_fit", ARTWORK_FIT_SETTINGS, "artwork_fit.",
             "Glyph centres fitted with the printed artwork before triangulating (input=images; "
             "docs/robustness.md, 'Centres fitted with the artwork'): "),
    Declared("extraction", EXTRACTION_SETTINGS, "extraction.",
             "Glyph extraction (input=images): "),
    Declared("diagnostics", DIAGNOSTIC_SETTINGS, "diagnostics.", "Diagnostics threshold: "),
    Declared("touch", TOUCH_SETTINGS),
    Declared("contact", CONTACT_SETTINGS, "contact_"),
    Declared("touch_weights", WEIGHT_SETTINGS, "touch_weights.",
             "Per-cell weights of the touch stage (docs/touch.md): "),
    Declared("elastomer", ELASTOMER_OVERRIDES, "elastomer."),
)
"""Every table the decoder node declares, in order."""


def table_of(name: str) -> Declared:
    """The :data:`DECODER_TABLES` entry of one settings object."""
    for declared in DECODER_TABLES:
        if declared.name == name:
            return declared
    raise KeyError(name)


def declared_names() -> dict[str, Any]:
    """Parameter name -> table row, for every table parameter of the decoder node."""
    return {d.prefix + row.name: row for d in DECODER_TABLES for row in d.table}
