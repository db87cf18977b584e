"""The camera worker process (camera_processes.py) gives the in-process pipeline's bytes."""
import pytest

from tactile_sl_common.images import to_gray
from tactile_sl_decoder.frames import bag_frames
from tactile_sl_decoder.pipeline import PatternSpec, PipelineParams, StereoPipeline

from ros_harness import BAGS

pytestmark = pytest.mark.slow


def _job(gray):
    from tactile_sl_decoder.camera_processes import CameraJob
    from tactile_sl_decoder.decode.grid import GridParams

    return CameraJob(gray.shape, None, GridParams(), None, None)


def test_the_same_points_cells_and_carry_as_in_process():
    frames = [(to_gray(f.left_image), to_gray(f.right_image), f.left_info, f.right_info)
              for f in bag_frames(BAGS / "two_contacts.mcap")]
    pattern = PatternSpec.load(None)
    here = StereoPipeline(pattern, None, PipelineParams(threads=1))
    there = StereoPipeline(pattern, None, PipelineParams(processes=True))
    try:
        for repeat in range(2):          # the second pass carries labels (and some cells)
            for left, right, li, ri in frames:
                a = here.process(left, right, li, ri)
                b = there.process(left, right, li, ri)
                assert a.points.tobytes() == b.points.tobytes()
                assert (a.carried, a.tracked) == (b.carried, b.tracked)
                for ga, gb in ((a.left, b.left), (a.right, b.right)):
                    assert (ga.label == gb.label).all() and (ga.row == gb.row).all()
                    assert gb.patches is None             # not sent back unless asked for
            if repeat == 0:
                assert b.carried > 0
        here.forget_frames()
        there.forget_frames()
        a, b = here.process(*frames[3]), there.process(*frames[3])
        assert a.carried == b.carried == 0
        there.keep_patches = True
        assert there.process(*frames[4]).left.patches is not None
        # an error of either half (the worker's, or the left one's here) is raised here
        # once both have ended, and the next frame goes on
        rig = there.rig(frames[0][2], frames[0][3])
        for cameras in ((rig.left, None), (None, rig.right)):
            with pytest.raises(AttributeError):
                there._procs.run((frames[0][0], frames[0][1]), cameras,
                                 (_job(frames[0][0]), _job(frames[0][1])),
                                 there.load_classifier(), there.memory.carries[0])
        after = there.process(*frames[5]).points.tobytes()
        assert after == here.process(*frames[5]).points.tobytes()
    finally:
        here.close()
        there.close()


def test_a_worker_that_cannot_start_is_reported_with_why(tmp_path):
    """A worker that cannot start is reported (a node polls before subscribing) with why."""
    from tactile_sl_decoder.camera_processes import CameraProcesses

    procs = CameraProcesses(str(tmp_path / "missing.pt"), None)
    try:
        with pytest.raises(RuntimeError, match=r"right camera worker process failed to start.*"
                                               r"missing\.pt"):
            procs.wait_ready(timeout=60.0)
    finally:
        procs.close()


def test_workers_report_ready_after_their_warm_up():
    """The worker answers ready (two synthetic frames run); frames then go through."""
    from tactile_sl_decoder.camera_processes import CameraProcesses

    procs = CameraProcesses(None, None)
    try:
        procs.wait_ready(timeout=60.0)
        assert procs.poll_ready()
        procs.wait_ready()                       # once is enough: no second handshake
    finally:
        procs.close()


def test_a_worker_whose_main_process_went_while_it_started_ends_quietly(capfd):
    """The main process ended (its end of the pipe closed) during the warm-up: no traceback.

    A decoder stopped within its first seconds did this; the worker's "ready" then hit a
    broken pipe and printed a traceback into the node's log.
    """
    import multiprocessing

    from tactile_sl_decoder.camera_processes import _serve

    context = multiprocessing.get_context("spawn")
    mine, theirs = context.Pipe()
    proc = context.Process(target=_serve, args=(theirs, None, None, 1), daemon=True)
    proc.start()
    theirs.close()
    mine.close()                              # long before its warm-up ends
    proc.join(timeout=120.0)
    assert proc.exitcode == 0
    assert "Traceback" not in capfd.readouterr().err


def test_ctrl_c_in_the_terminal_leaves_the_workers_to_the_main_process():
    """SIGINT reaches the whole process group; the workers ignore it and go on serving."""
    import os
    import signal
    import time

    frames = bag_frames(BAGS / "two_contacts.mcap")
    frame = next(iter(frames))
    left, right = to_gray(frame.left_image), to_gray(frame.right_image)
    pattern = PatternSpec.load(None)
    here = StereoPipeline(pattern, None, PipelineParams(threads=1))
    there = StereoPipeline(pattern, None, PipelineParams(processes=True))
    try:
        for pipe in (here, there):                                # workers ready
            pipe.process(left, right, frame.left_info, frame.right_info)
        expected = here.process(left, right, frame.left_info, frame.right_info)
        for pid in there.worker_pids:
            os.kill(pid, signal.SIGINT)
        time.sleep(0.5)
        got = there.process(left, right, frame.left_info, frame.right_info)
        assert got.points.tobytes() == expected.points.tobytes()
    finally:
        here.close()
        there.close()
