"""StreamMemory: what the pipeline keeps of the previous frame, and when it decodes in full."""
import numpy as np

from tactile_sl_decoder.classify.carry import CarryParams
from tactile_sl_decoder.decode.track import StreamMemory
from tactile_sl_decoder.glyphs import Glyphs


def _glyphs(n, row0=0):
    g = Glyphs(np.arange(n, dtype=np.float32), np.zeros(n, np.float32),
               np.zeros(n, np.uint8), np.ones(n, np.float32), 10.0, 100, 100)
    g.row = np.arange(row0, row0 + n, dtype=np.int32)
    g.col = np.zeros(n, np.int32)
    return g


def test_the_countdown_forces_a_full_decode_every_refresh_frames():
    memory = StreamMemory(CarryParams(refresh_frames=3))
    images = [_glyphs(4), _glyphs(4)]
    assert memory.carried_cells(images, 10) is None          # nothing remembered yet
    memory.remember(images, tracked=False)                   # a full decode: countdown 2
    assert memory.full_decode_in == 2 and memory.cells[0][0] is images[0].row
    memory.remember(images, tracked=True)
    memory.remember(images, tracked=True)
    assert memory.full_decode_in == 0                        # the next frame in full
    assert memory.carried_cells(images, 10) is None


def test_carrying_off_forgets_and_gives_no_carries():
    params = CarryParams()
    memory = StreamMemory(params)
    memory.remember([_glyphs(2), _glyphs(2)], tracked=False)
    assert memory.label_carries() == memory.carries
    params.enabled = False                                   # a live change
    assert memory.label_carries() == (None, None)
    assert memory.cells == [None, None] and memory.full_decode_in == 0


def test_cells_come_from_the_matched_previous_glyphs():
    memory = StreamMemory(CarryParams(refresh_frames=8))
    before = [_glyphs(3, row0=5), _glyphs(3, row0=7)]
    memory.remember(before, tracked=False)
    for carry in memory.carries:          # as LabelCarry.carry() leaves it: glyph i <- i
        carry.last = type("Match", (), {"source": np.array([2, 1, 0])})()
    now = [_glyphs(3), _glyphs(3)]
    left, right = memory.carried_cells(now, 10)
    assert left.tolist() == [70, 60, 50] and right.tolist() == [90, 80, 70]
