"""Messages -> what the page draws: cells placed by rest position, units, the contact cells."""
import math
from types import SimpleNamespace

import numpy as np
import pytest
import viewer_messages as msgs

from tactile_sl_common.clouds import CloudFormatError
from tactile_sl_viewer.view_model import (
    PadGeometry,
    contact_cells,
    depth_view,
    diagnostics_view,
    glyph_view,
    image_view,
    pressure_grid,
    slip_view,
    stamp_of,
    wrench_view,
)

PAD = msgs.PAD


def test_pressure_is_pressing_force_over_cell_area_at_the_cells_rest_position():
    field = msgs.field(5, {(1, 3): -0.02, (4, 0): 0.01, (2, 2): -0.005}, shift=(1.5e-4, -1e-4))
    grid = pressure_grid(field, PAD)
    assert grid.shape == (PAD.rows, PAD.cols)
    cell = PAD.pitch ** 2
    assert grid[1, 3] == pytest.approx(0.02 / cell / 1e3, rel=1e-5)      # kPa
    assert grid[2, 2] == pytest.approx(0.005 / cell / 1e3, rel=1e-5)
    assert grid[4, 0] == 0.0                        # pulling is no pressure
    assert np.isfinite(grid).all()                  # every cell decoded here
    assert (grid > 0).sum() == 2


def test_cells_not_decoded_are_nan_and_cells_off_the_pattern_are_left_out():
    small = PadGeometry(rows=4, cols=3, pitch=PAD.pitch)    # centred in the 6 x 5 field
    field = msgs.field(5, {(2, 2): -0.01})
    step = field.point_step
    first_cell_of_small = 1 * PAD.cols + 1                   # field cell (1, 1) is small's (0, 0)
    field.data = (field.data[: first_cell_of_small * step]
                  + field.data[(first_cell_of_small + 1) * step:])
    field.width -= 1
    grid = pressure_grid(field, small)
    assert grid.shape == (4, 3)
    assert math.isnan(grid[0, 0])                             # not decoded
    assert np.isfinite(grid).sum() == 11                      # the rest; outer cells left out
    assert grid[1, 1] == pytest.approx(0.01 / PAD.pitch ** 2 / 1e3, rel=1e-5)
    empty = msgs.field(5, {})
    empty.width = 0
    empty.data = b""
    assert np.isnan(pressure_grid(empty, PAD)).all()


def test_a_field_without_forces_is_refused_with_the_reason():
    field = msgs.field(5, {})
    field.fields = [f for f in field.fields if f.name not in ("fx", "fy", "fz")]
    with pytest.raises(CloudFormatError, match="fx"):
        pressure_grid(field, PAD)


def test_contact_cells_are_the_most_pressed_cells_counted_by_the_decoder():
    grid = np.array([[np.nan, 1.0, 5.0], [0.0, 3.0, 4.0]], np.float32)
    assert contact_cells(grid, 2).tolist() == [[0, 0, 1], [0, 0, 1]]
    assert contact_cells(grid, 3).tolist() == [[0, 0, 1], [0, 1, 1]]
    assert contact_cells(grid, 0).sum() == 0
    assert contact_cells(grid, 99).sum() == 4       # never a cell that does not press


def test_depth_is_micrometres_in_either_byte_order():
    metres = np.array([[0.0, 1e-4], [np.nan, 2.5e-5]])
    for big in (False, True):
        um = depth_view(msgs.depth(7, metres, big_endian=big))
        assert um.dtype == np.float32
        assert um[0, 1] == pytest.approx(100.0) and um[1, 1] == pytest.approx(25.0)
        assert math.isnan(um[1, 0])
    bad = msgs.depth(7, metres)
    bad.encoding = "mono8"
    with pytest.raises(ValueError, match="32FC1"):
        depth_view(bad)


def test_glyphs_carry_labels_and_whether_their_cell_was_decoded():
    view = glyph_view(msgs.symbols(3, n=4))
    assert view["u"].tolist() == [0, 5, 10, 15]
    assert view["label"].tolist() == [0, 1, 2, 255]
    assert view["decoded"].tolist() == [1, 0, 1, 0]


def test_image_is_copied_out_of_the_message():
    msg = msgs.image(3, value=10)
    gray = image_view(msg)
    assert gray.shape == (48, 64) and gray[0, 0] == 10
    assert not np.shares_memory(gray, np.frombuffer(msg.data, np.uint8))


def test_wrench_stamp_slip_and_diagnostics_views():
    w = wrench_view(msgs.wrench(1_700_000_000_123_456_789, force=(0.1, -0.2, -1.5)))
    assert w["force"] == pytest.approx([0.1, -0.2, -1.5])
    assert stamp_of(msgs.wrench(1_700_000_000_123_456_789)) == 1_700_000_000_123_456_789
    v3 = SimpleNamespace(x=0.6, y=0.8, z=0.0)
    slip = slip_view(SimpleNamespace(state=2, stick_ratio=0.4, slip_margin=float("nan"),
                                     friction_coefficient=0.9, direction=v3))
    assert slip["state_name"] == "partial slip" and slip["slip_margin"] is None
    assert slip["direction"] == pytest.approx([0.6, 0.8, 0.0])
    statuses = [SimpleNamespace(name="tactile/decoder: input left", hardware_id="tactile",
                                level=b"\x00", message="30 Hz"),
                SimpleNamespace(name="other/decoder: input left", hardware_id="other",
                                level=2, message="silent")]
    mine = diagnostics_view(SimpleNamespace(status=statuses), "tactile")
    assert mine == [{"name": "tactile/decoder: input left", "level": "OK", "message": "30 Hz"}]
    everyone = diagnostics_view(SimpleNamespace(status=statuses), "nobody")
    assert [d["level"] for d in everyone] == ["OK", "ERROR"]
