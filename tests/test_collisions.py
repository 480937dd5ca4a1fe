"""Collision counting on small hand-written LIGGGHTS local dumps with known contact sequences."""

from pathlib import Path

import numpy as np
import pytest

from pbmdem.atomic import write_csv
from pbmdem.dem import collisions
from pbmdem.dem.collisions import aggregate, window_starts
from pbmdem.dem.dumps import DumpFormatError, read_dump


def count_pair_collisions(snaps, class_of, k, stride=1):
    """(K, K) contacts that begin after the first snapshot, per class pair (raw count)."""
    s = window_starts(snaps, snaps.steps[0] if snaps.frames else 0, stride=stride)
    ci, cj = class_of[s.first], class_of[s.second]
    i, j = np.minimum(ci, cj), np.maximum(ci, cj)
    return np.bincount(i * k + j, minlength=k * k).reshape(k, k)


def count_wall_collisions(snaps, class_of, k):
    s = window_starts(snaps, snaps.steps[0], wall=True)
    return np.bincount(s.first * k + class_of[s.second], minlength=2 * k).reshape(2, k)


def frame(step: int, rows: list[tuple], kind: str = "ENTRIES") -> str:
    head = (
        f"ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF {kind}\n{len(rows)}\n"
        "ITEM: BOX BOUNDS ff ff ff\n-1 1\n-1 1\n-1 1\n"
        f"ITEM: {kind} c_pairs[1] c_pairs[2] c_pairs[4] \n"
    )
    return head + "".join(" ".join(str(v) for v in r) + " \n" for r in rows)


def write(tmp_path: Path, name: str, frames: list[str]) -> Path:
    path = tmp_path / name
    path.write_text("".join(frames))
    return path


# Particles 1, 2 are class 0; 3, 4 class 1. Sequence over frames 0..4:
#  (1,2): in contact at frame 0 and stays             -> 0 new contacts (began before the window)
#  (1,3): touches at 1, separates at 2, touches at 3  -> 2 new contacts
#  (2,4): touches at 2 and stays through 4, listed as (4,2) at frame 3 -> 1
#  (3,4): listed at frame 1 with negative overlap (liquid bridge, not touching), touches at 4 -> 1
SEQUENCE = [
    frame(100, [(1, 2, 1e-5)]),
    frame(105, [(1, 2, 1e-5), (1, 3, 2e-6), (3, 4, -1e-5)]),
    frame(110, [(2, 1, 1e-5), (2, 4, 1e-6)]),
    frame(115, [(1, 2, 1e-5), (3, 1, 3e-6), (4, 2, 2e-6)]),
    frame(120, [(1, 2, 1e-5), (2, 4, 2e-6), (3, 4, 1e-6)]),
]
CLASS_OF = np.array([-1, 0, 0, 1, 1])


def test_known_contact_sequence(tmp_path):
    snaps = read_dump(write(tmp_path, "pairs.dump", SEQUENCE), 3)
    assert snaps.frames == 5
    assert snaps.steps.tolist() == [100, 105, 110, 115, 120]
    counts = count_pair_collisions(snaps, CLASS_OF, 2)
    # (1,3) twice and (2,4) once are class (0,1); (3,4) once is (1,1); (1,2) never counts
    assert counts.tolist() == [[0, 3], [0, 1]]


def test_stride_uses_every_second_snapshot(tmp_path):
    snaps = read_dump(write(tmp_path, "pairs.dump", SEQUENCE), 3)
    counts = count_pair_collisions(snaps, CLASS_OF, 2, stride=2)
    # frames 0, 2, 4 only: (2,4) begins at 2; (3,4) begins at 4; (1,3) is never seen
    assert counts.tolist() == [[0, 1], [0, 1]]


def test_new_contacts_counts_a_mesh_contact_once_per_particle():
    # particle 7 touches two triangles of the impeller (mesh 1) in frames 1 and 2
    frame_idx = np.array([1, 1, 2, 2, 2])
    key = np.array([17, 17, 17, 17, 5])
    begins, _ = collisions.contact_starts(frame_idx, key)
    assert begins.sum() == 2  # key 17 begins at frame 1 once; key 5 begins at frame 2


def test_wall_table_separates_bowl_and_impeller(tmp_path):
    frames = [
        frame(0, [(0, 1, 1e-6)]),
        frame(5, [(0, 1, 1e-6), (1, 3, 1e-6), (1, 3, 2e-6)]),
        frame(10, [(1, 3, 1e-6), (0, 4, 1e-6), (1, 1, -1e-6)]),
    ]
    snaps = read_dump(write(tmp_path, "walls.dump", frames), 3)
    counts = count_wall_collisions(snaps, CLASS_OF, 2)
    assert counts.tolist() == [[0, 1], [0, 1]]  # bowl: particle 4 (class 1); impeller: particle 3 once


def test_empty_dump_gives_no_frames(tmp_path):
    snaps = read_dump(write(tmp_path, "pairs.dump", []), 3)
    assert snaps.frames == 0
    assert count_pair_collisions(snaps, CLASS_OF, 2).sum() == 0


def test_frames_without_contacts(tmp_path):
    snaps = read_dump(write(tmp_path, "pairs.dump", [frame(0, []), frame(5, [(1, 3, 1e-6)]), frame(10, [])]), 3)
    assert snaps.frames == 3
    assert count_pair_collisions(snaps, CLASS_OF, 2).tolist() == [[0, 1], [0, 0]]


def test_truncated_file_gives_clear_error(tmp_path):
    text = "".join(SEQUENCE)
    cut = text[: text.rindex("2 4 2e-06")]  # the run died while writing the last frame
    path = tmp_path / "pairs.dump"
    path.write_text(cut)
    with pytest.raises(DumpFormatError, match="truncated"):
        read_dump(path, 3)


def test_truncated_header_gives_clear_error(tmp_path):
    path = tmp_path / "pairs.dump"
    path.write_text("".join(SEQUENCE) + "ITEM: TIMESTEP\n125\nITEM: NUMB")
    with pytest.raises(DumpFormatError, match="truncated|malformed"):
        read_dump(path, 3)


def test_missing_file_gives_clear_error(tmp_path):
    with pytest.raises(DumpFormatError, match="does not exist"):
        read_dump(tmp_path / "nope.dump", 3)


def test_not_a_dump(tmp_path):
    path = tmp_path / "pairs.dump"
    path.write_text("hello\n")
    with pytest.raises(DumpFormatError, match="header"):
        read_dump(path, 3)


def test_previous_contact_frame_is_reported(tmp_path):
    snaps = read_dump(write(tmp_path, "pairs.dump", SEQUENCE), 3)
    s = window_starts(snaps, 100)
    # (1,3) begins at 105 (no earlier contact) and again at 115 (previous contact at 105)
    rows = sorted(zip(s.first.tolist(), s.second.tolist(), s.step.tolist(), s.prev_step.tolist()))
    assert rows == [(1, 3, 105, -1), (1, 3, 115, 105), (2, 4, 110, -1), (3, 4, 120, -1)]
    assert len(window_starts(snaps, 110).step) == 2  # only contacts beginning after step 110


def test_pair_table_normalises_per_pair():
    counts = np.array([[10, 6], [0, 4]])
    enc = np.array([[4, 3], [0, 1]])
    median = np.array([[0.1, 0.2], [np.nan, 0.3]])
    tally = collisions.Tally(counts, enc, np.zeros((2, 2, 17)), median)
    n = np.array([5, 3])
    table = collisions.pair_table(
        tally, n, [0.002, 0.003], 2.0, {"point_id": "p", "rpm": 100.0, "distribution": "d", "replicate": 0}
    )
    assert table[["class_i", "class_j"]].values.tolist() == [[0, 0], [0, 1], [1, 1]]
    # pairs: 5*4/2 = 10 on the diagonal, 5*3 = 15 across, 3*2/2 = 3
    np.testing.assert_allclose(table["frequency_per_pair"], [10 / (10 * 2), 6 / (15 * 2), 4 / (3 * 2)])
    np.testing.assert_allclose(table["frequency"], [5.0, 3.0, 2.0])
    np.testing.assert_allclose(table["encounter_frequency_per_pair"], [4 / (10 * 2), 3 / (15 * 2), 1 / (3 * 2)])
    np.testing.assert_allclose(table["impact_velocity_median"], [0.1, 0.2, 0.3])


def test_replicate_mean_and_standard_error(tmp_path):
    rows = []
    for rep, (enc, f) in enumerate([(2.0, 0.1), (4.0, 0.3), (6.0, 0.2)]):
        rows.append(
            {
                "point_id": "p",
                "rpm": 100.0,
                "distribution": "d",
                "replicate": rep,
                "class_i": 0,
                "class_j": 0,
                "d_i": 0.002,
                "d_j": 0.002,
                "n_i": 10,
                "n_j": 10,
                "n_total": 10,
                "collisions": 2 * enc,
                "sampling_time": 1.0,
                "frequency": 2 * enc,
                "frequency_per_pair": 2 * f,
                "encounters": enc,
                "encounter_frequency_per_pair": f,
                "impact_velocity_median": 0.5,
            }
        )
    paths = []
    for rep, row in enumerate(rows):
        paths.append(tmp_path / f"rep{rep}.csv")
        write_csv(paths[-1], __import__("pandas").DataFrame([row]))
    grid = aggregate(paths, tmp_path / "grid.csv")
    assert grid["n_replicates"].tolist() == [3]
    assert grid["encounters"].tolist() == [4.0]
    assert grid["encounter_frequency_per_pair"].iloc[0] == pytest.approx(0.2)
    assert grid["encounter_frequency_per_pair_se"].iloc[0] == pytest.approx(0.1 / np.sqrt(3))


def test_a_damaged_row_is_located_by_line_byte_and_frame(tmp_path):
    text = "".join(SEQUENCE)
    bad = text.replace("3 1 3e-06", "3 1 \x07\x9a", 1)  # frame 4 (step 115), its second row
    path = tmp_path / "pairs.dump"
    path.write_bytes(bad.encode("latin-1"))
    line = text[: text.index("3 1 3e-06")].count("\n") + 1
    byte = len(text[: text.index("3 1 3e-06")].encode())
    with pytest.raises(DumpFormatError) as err:
        read_dump(path, 3)
    assert f"corrupt dump: {path}: line {line} (byte {byte}), frame 4 (step 115)" in str(err.value)
    assert "an entry row of 3 finite numbers expected" in str(err.value)


def test_find_damage_accepts_a_well_formed_dump_and_rejects_a_step_going_back(tmp_path):
    from pbmdem.dem.dumps import find_damage

    assert find_damage(write(tmp_path, "pairs.dump", SEQUENCE)) is None
    path = write(tmp_path, "back.dump", [SEQUENCE[0], SEQUENCE[2], SEQUENCE[1]])
    assert "time step 105 does not follow 110" in find_damage(path)


@pytest.mark.parametrize("value", ["0", "2.5", "-3"])
def test_an_impossible_particle_id_is_corruption_located_by_line_and_frame(tmp_path, value):
    text = "".join(SEQUENCE)
    at = text.index("2 4 1e-06")  # frame 3 (step 110), its second row
    path = tmp_path / "pairs.dump"
    path.write_text(text[:at] + f"{value} 4 1e-06" + text[at + len("2 4 1e-06") :])
    line = text[:at].count("\n") + 1
    with pytest.raises(DumpFormatError) as err:
        read_dump(path, 3, ids=(0, 1))
    assert f"corrupt dump: {path}: line {line} (byte {at}), frame 3 (step 110): column 1 = {float(value):g}" in str(
        err.value
    )
    assert read_dump(path, 3).frames == 5  # the same rows without the id check: the check is what refuses them


def binary_frame(step: int, rows: np.ndarray, ranks: int = 1) -> bytes:
    """One frame of a binary LIGGGHTS 3.8 `dump custom` (*.bin), its rows split over `ranks` chunks."""
    from pbmdem.dem.dumps import BINARY_HEADER

    rows = np.asarray(rows, dtype="<f8")
    head = np.zeros(1, BINARY_HEADER)
    head["step"], head["rows"], head["boundary"] = step, len(rows), 1
    head["box"] = (-1, 1, -1, 1, -1, 1)
    head["size_one"], head["chunks"] = rows.shape[1], ranks
    out = head.tobytes()
    for part in np.array_split(rows, ranks):
        out += np.int32(part.size).tobytes() + part.tobytes()
    return out


def positions(step: int, n: int = 4) -> np.ndarray:
    ids = np.arange(1, n + 1)
    return np.column_stack([ids, 0.01 * ids, -0.02 * ids, step * 1e-6 + 0 * ids, ids, 2 * ids, 3 * ids])


def test_a_binary_dump_reads_back_every_frame_and_chunk(tmp_path):
    from pbmdem.dem.dumps import read_trajectories

    path = tmp_path / "positions.bin"
    path.write_bytes(binary_frame(100, positions(100)) + binary_frame(110, positions(110), ranks=2))
    snaps = read_dump(path, 7, ids=(0,))
    assert snaps.steps.tolist() == [100, 110]
    assert snaps.offsets.tolist() == [0, 4, 8]
    np.testing.assert_array_equal(snaps.data, np.vstack([positions(100), positions(110)]))
    traj = read_trajectories(path, 4)
    assert traj.ids.tolist() == [1, 2, 3, 4]
    assert traj.pos[1, 2].tolist() == positions(110)[2, 1:4].tolist()
    assert traj.vel[0, 3].tolist() == [4.0, 8.0, 12.0]


def test_a_truncated_binary_dump_names_byte_and_frame(tmp_path):
    from pbmdem.dem import engine
    from pbmdem.dem.dumps import find_damage

    whole = binary_frame(100, positions(100)) + binary_frame(110, positions(110))
    path = tmp_path / "positions.bin"
    path.write_bytes(whole[:-20])
    first = len(binary_frame(100, positions(100)))
    with pytest.raises(
        DumpFormatError,
        match=rf"positions.bin: byte {first}, frame 2, after the frame at step 100: "
        r"truncated: the frame at step 110 announces 28 values, the file ends first",
    ):
        read_dump(path, 7)
    assert engine.dump_steps(path) == [100]  # the well-formed frames before the damage
    assert "truncated" in find_damage(path)
    path.write_bytes(whole[: first + 30])
    assert "bytes left of a 100-byte frame header" in find_damage(path)


def test_binary_dump_damage_steps_values_and_ids(tmp_path):
    from pbmdem.dem.dumps import find_damage

    path = tmp_path / "positions.bin"
    good = binary_frame(100, positions(100)) + binary_frame(110, positions(110))
    path.write_bytes(good)
    assert find_damage(path) is None
    path.write_bytes(binary_frame(110, positions(110)) + binary_frame(100, positions(100)))
    assert "time step 100 does not follow 110" in find_damage(path)
    with pytest.raises(DumpFormatError, match="time step 100 does not follow 110"):
        read_dump(path, 7)
    rows = positions(110)
    rows[2, 4] = np.nan
    path.write_bytes(binary_frame(100, positions(100)) + binary_frame(110, rows))
    with pytest.raises(
        DumpFormatError, match=r"non-finite value nan in column 5 of entry row 3 of the frame at step 110"
    ):
        read_dump(path, 7)
    nan_at = len(binary_frame(100, positions(100))) + 104 + 8 * (2 * 7 + 4)
    assert f"byte {nan_at}, frame 2 (step 110): non-finite value nan" in find_damage(path)
    rows = positions(110)
    rows[3, 0] = 2.5
    path.write_bytes(binary_frame(100, positions(100)) + binary_frame(110, rows))
    row_at = len(binary_frame(100, positions(100))) + 104 + 8 * 3 * 7
    with pytest.raises(
        DumpFormatError, match=rf"byte {row_at}, frame 2 \(step 110\), entry row 4: column 1 = 2.5 is not"
    ):
        read_dump(path, 7, ids=(0,))
    with pytest.raises(DumpFormatError, match="rows of 7 values, 3 expected"):
        read_dump(path, 3)
