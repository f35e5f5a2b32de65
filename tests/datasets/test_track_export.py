"""OV2SLAM track exports (cfo_kitti04, read its SOURCE.md): real KITTI 04 tracks without images."""
from __future__ import annotations

import numpy as np
import pytest

from gevi_cli.datasets import track_export
from gevi_cli.datasets.track_export import TrackExport, open_track_export
from gevi_cli.errors import DataError, GeviError, LayoutError
from gevi_cli.frontend.export import ExportFrontEnd
from support import shared_path

B_GRAY, B_COLOUR, F = 0.537150653267924, 0.5433, 707.0912


def _paths(colour: bool):
    root = shared_path("cfo_kitti04")
    folder = root / "data" / "ov2slam_data" / ("ov2slam_data_kitti_04" if colour else "ov2slam_data_kitti_04_gray")
    calib = root / "calib" / ("colour_calib.txt" if colour else "gray_calib.txt")
    return folder, calib, root / "data" / "gt_poses" / "kitti_gt_pose" / "04.txt"


@pytest.fixture(scope="module")
def gray() -> TrackExport:
    folder, calib, gt = _paths(False)
    return open_track_export(folder, calib, groundtruth=gt)


def test_gray_export_counts_as_in_source_md(gray):
    assert track_export.detect(gray.path)
    assert gray.kind == "ov2slam-tracks" and gray.name == "ov2slam_data_kitti_04_gray"
    assert len(gray) == 271 and gray.imu is None and gray.pair == ("P0", "P1") and not gray.colour
    np.testing.assert_array_equal(gray.stamps_ns, np.arange(271) * 100_000_000)
    frames = list(gray.frames())
    assert [f.index for f in frames] == list(range(271))
    keyframes = [f.index for f in frames if f.stereo is not None]
    assert len(keyframes) == 163
    assert keyframes[:4] == [0, 2, 4, 6] and keyframes[-4:] == [265, 267, 269, 270]
    np.testing.assert_array_equal(gray.keyframe_ids, keyframes)
    tracked = frames[1:]
    counts = [len(f.obs) for f in tracked]
    assert min(counts) == 102 and max(counts) == 315 and np.median(counts) == 204
    flagged = sum(int(f.outlier.sum()) for f in tracked) / sum(counts)
    assert flagged == pytest.approx(0.073, abs=0.0005)
    assert np.median([len(f.stereo) for f in frames if f.stereo is not None]) == 266
    for f in frames[:3]:
        assert f.obs.ids.dtype == np.int64 and f.obs.uv.shape == (len(f.obs), 2) and f.outlier.dtype == bool
        assert f.t_ns == f.index * 100_000_000
    # frame 0 has no track block: its observations are the left points of its stereo matches
    np.testing.assert_array_equal(frames[0].obs.ids, frames[0].stereo.ids)
    np.testing.assert_array_equal(frames[0].obs.uv, frames[0].stereo.uv_left)
    assert not frames[0].outlier.any()
    assert gray.warnings == []
    assert [f.index for f in gray.frames(start=5, stop=11, step=3)] == [5, 8]


def test_tracks_refer_to_the_latest_keyframe(gray):
    frames = list(gray.frames())
    found = total = 0
    latest = frames[0].stereo
    for f in frames[1:]:
        found += int(np.isin(f.obs.ids, latest.ids).sum())
        total += len(f.obs)
        if f.stereo is not None:
            latest = f.stereo
    assert found / total > 0.90


def test_gray_camera_and_groundtruth(gray):
    cam = gray.camera
    assert (cam.width, cam.height) == (1226, 370)
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (F, F, 601.8873, 183.1104)
    assert cam.baseline == pytest.approx(B_GRAY, rel=1e-6)
    np.testing.assert_allclose(cam.T_B_C0, np.eye(4), atol=1e-12)
    gt = gray.groundtruth
    assert gt.frame == "cam0" and gt.indexed and len(gt) == 271
    np.testing.assert_array_equal(gt.t_ns, gray.stamps_ns)
    assert gt.path_length_m == pytest.approx(394, abs=5)


def test_colour_export_uses_cam2_cam3():
    folder, calib, _ = _paths(True)
    export = open_track_export(folder, calib)
    assert export.name == "ov2slam_data_kitti_04" and export.pair == ("P2", "P3") and export.colour
    assert len(export) == 271 and len(export.keyframe_ids) == 177 and export.groundtruth is None
    cam = export.camera
    assert cam.baseline == pytest.approx(B_COLOUR, rel=1e-6)
    # T_20 = [I | (0.0663, 0, 0)] maps cam0 to cam2 coordinates: cam2 sits at x = -0.0663 m in cam0
    np.testing.assert_allclose(cam.T_B_C0[:3, 3], [-0.0663, 0, 0], atol=1e-9)
    np.testing.assert_allclose(cam.T_B_C0[:3, :3], np.eye(3))
    # the gray calib on the colour export: the gray pair, with a warning
    gray_calib = _paths(False)[1]
    export = open_track_export(folder, gray_calib)
    assert export.pair == ("P0", "P1") and export.camera.baseline == pytest.approx(B_GRAY, rel=1e-6)
    assert any("no P2/P3" in w for w in export.warnings)


def test_reading_every_frame_records_the_read_time():
    """Every frame reads; the parse time is recorded for the front end's timings (how long it takes,
    next to reading the bare files, is scripts/bench_io.py --export's)."""
    folder, calib, _ = _paths(False)
    export = TrackExport(folder, calib)
    assert len(list(export.frames())) == len(export) == 271
    assert export.read_seconds > 0


def test_export_front_end(gray):
    fe = ExportFrontEnd(gray)
    assert fe.camera is gray.camera and set(fe.timings) == {"read"}
    f0, f1, f2 = gray.frame(0), gray.frame(1), gray.frame(2)
    assert fe.keyframe_decision(f0) is True and fe.keyframe_decision(f1) is False and fe.keyframe_decision(f2) is True
    assert fe.track(f1) is f1.obs  # flags ignored by default
    assert fe.keyframe(f2) is f2.stereo
    with pytest.raises(GeviError, match="frame 1 is not a keyframe"):
        fe.keyframe(f1)
    strict = ExportFrontEnd(gray, use_outlier_flags=True)
    kept = strict.track(f1)
    assert f1.outlier.any() and len(kept) == int((~f1.outlier).sum())
    np.testing.assert_array_equal(kept.ids, f1.obs.ids[~f1.outlier])
    np.testing.assert_array_equal(kept.uv, f1.obs.uv[~f1.outlier])


# ------------------------------------------------------------------------------ broken inputs
def _small_copy(tmp_path, n_blocks=4, name="ov2slam_data_kitti_04_gray"):
    """The first ``n_blocks`` frames' tracks and the keyframes among frames 0..n_blocks, as text lines."""
    folder, calib, _ = _paths(False)
    out = tmp_path / name
    out.mkdir()
    tracks = (folder / "ov2slam_pnp_data_seq04.txt").read_text().splitlines()[:8 * n_blocks]
    stereo_all = (folder / "ov2slam_stereo_matches.txt").read_text().splitlines()
    stereo = []
    for b in range(0, len(stereo_all), 6):
        if int(stereo_all[b]) <= n_blocks:
            stereo += stereo_all[b:b + 6]
    (out / "ov2slam_pnp_data_seq04.txt").write_text("\n".join(tracks) + "\n")
    (out / "ov2slam_stereo_matches.txt").write_text("\n".join(stereo) + "\n")
    return out, calib, tracks, stereo


def test_small_copy_reads(tmp_path):
    out, calib, _, _ = _small_copy(tmp_path)
    export = open_track_export(out, calib)
    assert len(export) == 5 and list(export.keyframe_ids) == [0, 2, 4]


def test_truncated_tracks_file(tmp_path):
    out, calib, tracks, _ = _small_copy(tmp_path)
    (out / "ov2slam_pnp_data_seq04.txt").write_text("\n".join(tracks[:-3]) + "\n")
    with pytest.raises(DataError, match=r"ov2slam_pnp_data_seq04\.txt:29: 29 lines is not a multiple of 8") as err:
        open_track_export(out, calib)
    assert "\n" not in str(err.value)


def test_truncated_stereo_file(tmp_path):
    out, calib, _, stereo = _small_copy(tmp_path)
    (out / "ov2slam_stereo_matches.txt").write_text("\n".join(stereo[:-1]) + "\n")
    with pytest.raises(DataError, match=r"ov2slam_stereo_matches\.txt:17: 17 lines is not a multiple of 6"):
        open_track_export(out, calib)


def test_non_numeric_token(tmp_path):
    out, calib, tracks, _ = _small_copy(tmp_path)
    tokens = tracks[9].split()
    tokens[3] = "abc"
    tracks[9] = " ".join(tokens)
    (out / "ov2slam_pnp_data_seq04.txt").write_text("\n".join(tracks) + "\n")
    message = r"ov2slam_pnp_data_seq04\.txt:10: value 4 'abc' is not a number \(line 2 of its block: left y\)"
    with pytest.raises(DataError, match=message):
        open_track_export(out, calib)


def test_line_lengths_differ_within_a_block(tmp_path):
    out, calib, tracks, _ = _small_copy(tmp_path)
    tracks[12] = " ".join(tracks[12].split()[:-1])  # frame 2's scale line loses a value
    (out / "ov2slam_pnp_data_seq04.txt").write_text("\n".join(tracks) + "\n")
    with pytest.raises(DataError, match=r"ov2slam_pnp_data_seq04\.txt:13: has \d+ values but line 9 of the same block"):
        open_track_export(out, calib)


def test_stereo_block_errors(tmp_path):
    out, calib, tracks, stereo = _small_copy(tmp_path)
    (out / "ov2slam_pnp_data_seq04.txt").write_text("\n".join(tracks) + "\n")
    bad = list(stereo)
    bad[6 + 4] = " ".join(bad[6 + 4].split()[:-2])  # keyframe 2: right y shorter
    (out / "ov2slam_stereo_matches.txt").write_text("\n".join(bad) + "\n")
    with pytest.raises(DataError, match=r"ov2slam_stereo_matches\.txt:11: has \d+ values but line 8"):
        open_track_export(out, calib)
    bad = list(stereo)
    bad[0] = "0 1"
    (out / "ov2slam_stereo_matches.txt").write_text("\n".join(bad) + "\n")
    with pytest.raises(DataError, match=r"stereo_matches\.txt:1: the first line of a keyframe block"):
        open_track_export(out, calib)
    bad = stereo[6:]  # no keyframe 0
    (out / "ov2slam_stereo_matches.txt").write_text("\n".join(bad) + "\n")
    with pytest.raises(DataError, match="no stereo matches for frame 0"):
        open_track_export(out, calib)
    bad = list(stereo)
    bad[12] = "9"  # keyframe beyond the 5 frames
    (out / "ov2slam_stereo_matches.txt").write_text("\n".join(bad) + "\n")
    with pytest.raises(DataError, match=r"stereo_matches\.txt:13: keyframe 9 is outside the 5 frames"):
        open_track_export(out, calib)


def test_calib_errors(tmp_path):
    out, calib, _, _ = _small_copy(tmp_path)
    no_p1 = tmp_path / "calib_no_p1.txt"
    no_p1.write_text("".join(line + "\n" for line in calib.read_text().splitlines() if not line.startswith("P1")))
    with pytest.raises(DataError, match=r"calib_no_p1\.txt: has no P1 row"):
        open_track_export(out, no_p1)
    short = tmp_path / "calib_short.txt"
    short.write_text("P0: 1 2 3\n")
    with pytest.raises(DataError, match=r"calib_short\.txt:1: 'P0' has 3 numbers, expected 12"):
        open_track_export(out, short)
    with pytest.raises(GeviError, match=r"missing\.txt: no such calib file"):
        open_track_export(out, tmp_path / "missing.txt")
    with pytest.raises(LayoutError, match=r"needs --calib FILE \(a KITTI calib\.txt\)"):
        open_track_export(out, None)


def test_layout_errors(tmp_path):
    out, calib, _, _ = _small_copy(tmp_path)
    (out / "ov2slam_stereo_matches.txt").unlink()
    assert not track_export.detect(out)
    with pytest.raises(LayoutError, match="not an OV2SLAM track export"):
        open_track_export(out, calib)
    with pytest.raises(LayoutError, match=r"missing ov2slam_stereo_matches\.txt"):
        TrackExport(out, calib)
    with pytest.raises(GeviError, match="no such file or folder"):
        open_track_export(tmp_path / "nope", calib)
