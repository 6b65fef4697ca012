"""Corrupt session files: a damaged chunk is one clear error naming its time range in export, eval and
info (CRCs are checked on every read), and `recover` keeps everything but that chunk."""

from __future__ import annotations

import shutil

import pytest

from teleprev.errors import SessionError
from teleprev.session.reader import SessionReader
from teleprev.session.records import parse_chunk
from tests.helpers.cli import teleprev
from tests.helpers.faults import chunk_spans, damage_chunk, flip_byte, has_traceback, mcap_opens


@pytest.fixture
def session(sim_session):
    return sim_session  # never changed here: every damage is done to a copy


def _copy(session, tmp_path, name):
    dst = tmp_path / name
    shutil.copy(session, dst)
    return dst


def _one_error_line(run) -> str:
    assert not has_traceback(run.stdout + run.stderr), run.stderr
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, run.stderr
    return lines[0]


def _crc_flip(path, index):
    """Flip a byte of the index-th chunk's stored CRC: the records still decompress, and only the CRC
    check can tell (a flip inside the compressed bytes may instead break zstd, depending on the data)."""
    offset, _, start, end = chunk_spans(path)[index]
    flip_byte(path, offset + 9 + 24)  # opcode, length; then start, end, uncompressed size; then the CRC
    return start, end


def _zstd_breaking_flip(path, index):
    """Flip a byte of the zstd frame of the index-th chunk so that it no longer decompresses."""
    offset, length, start, end = chunk_spans(path)[index]
    body = path.read_bytes()[offset + 9:offset + length]
    data_at = offset + length - len(parse_chunk(body, 0, len(body)).data)
    flip_byte(path, data_at + 8)
    return start, end


@pytest.mark.parametrize("damage", ["crc", "zstd"])
def test_export_info_and_eval_name_the_damaged_chunk(session, tmp_path, damage):
    path = _copy(session, tmp_path, f"{damage}.mcap")
    n = len(chunk_spans(path))
    start, end = (_crc_flip if damage == "crc" else _zstd_breaking_flip)(path, n // 2)
    with SessionReader(session) as clean:
        t0 = clean.start_ns
    span = f"log time {(start - t0) / 1e9:.3f}-{(end - t0) / 1e9:.3f} s"
    why = "CRC mismatch" if damage == "crc" else "zstd chunk does not decompress"

    root = tmp_path / "out"
    run = teleprev("export", path, "--repo-id", "lab/x", "--root", root)
    line = _one_error_line(run)
    assert run.returncode == 2 and span in line and why in line and "teleprev recover" in line
    assert not root.exists() and not list(tmp_path.glob(".out.export-*"))

    run = teleprev("info", path)
    line = _one_error_line(run)
    assert run.returncode == 2 and span in line and why in line

    run = teleprev("eval", path, "--out", tmp_path / "report.json")
    assert run.returncode == 1 and not has_traceback(run.stdout + run.stderr)
    assert span.split()[-2] in run.stdout.replace("\n", " ")  # the damaged range, in the failed-session list


def test_recover_keeps_everything_but_the_damaged_chunk(session, tmp_path):
    path = _copy(session, tmp_path, "flip.mcap")
    spans = chunk_spans(path)
    start, end = damage_chunk(path, 1)
    out = tmp_path / "saved.mcap"
    run = teleprev("recover", path, "-o", out)
    assert run.returncode == 0 and not has_traceback(run.stdout + run.stderr), run.stderr
    assert "damaged" in run.stdout and "lost" in run.stdout
    assert mcap_opens(out)
    with SessionReader(session) as clean, SessionReader(out) as saved:
        for topic, info in clean.topics.items():
            kept = set(saved.log_times(topic).tolist()) if topic in saved.topics else set()
            lost = set(clean.log_times(topic).tolist()) - kept
            assert all(start <= t <= end for t in lost), topic  # only the damaged chunk's messages
        assert saved.end_ns == clean.end_ns  # everything after the damage is there
    assert len(spans) > 3


def test_a_changed_byte_outside_the_chunks_is_named_and_recover_loses_nothing(session, tmp_path):
    import struct

    data = session.read_bytes()
    summary_start = struct.unpack_from("<Q", data, len(data) - 8 - 29 + 9)[0]
    offset, length, _, _ = chunk_spans(session)[1]
    for name, at, said in (("index", offset + length + 20, "outside the chunks"),  # the message index after a chunk
                           ("summary", summary_start + 30, "summary CRC mismatch")):
        path = _copy(session, tmp_path, f"{name}.mcap")
        flip_byte(path, at, 0x04)
        run = teleprev("info", path)
        line = _one_error_line(run)
        assert run.returncode == 2 and said in line, line
        out = tmp_path / f"{name}.saved.mcap"
        run = teleprev("recover", path, "-o", out)
        assert run.returncode == 0, run.stderr
        with SessionReader(session) as clean, SessionReader(out) as saved:
            assert {t: i.message_count for t, i in saved.topics.items()} == {
                t: i.message_count for t, i in clean.topics.items()
            }


def _metadata_record(path, name: str) -> tuple[int, int]:
    """(offset, length) of the metadata record `name`, from the file's summary."""
    from teleprev.session import records as mr

    with open(path, "rb") as f:
        summary = mr.read_summary(f, path.stat().st_size)
    return next((offset, length) for n, offset, length in summary.metadata if n == name)


def test_a_changed_byte_in_the_task_text_is_an_error_not_a_dataset(session, tmp_path):
    """The data section's CRC covers the metadata records: export and eval check it before they use them."""
    path = _copy(session, tmp_path, "tasks.mcap")
    offset, length = _metadata_record(path, "tasks")
    data = path.read_bytes()
    at = data.index(b"and", offset, offset + length)  # "pick up the cube and place it ..."
    flip_byte(path, at + 1, 0x01)  # "aod"
    for args in (["export", path, "--repo-id", "lab/t", "--root", tmp_path / "ds"], ["info", path]):
        run = teleprev(*args)
        line = _one_error_line(run)
        assert run.returncode == 2 and "outside the chunks" in line and "teleprev recover" in line, line
    assert not (tmp_path / "ds").exists()
    run = teleprev("eval", path)
    assert run.returncode == 1 and "outside the chunks" in " ".join(run.stdout.split())


def test_a_metadata_length_past_the_end_of_the_file_is_named_not_allocated(session, tmp_path):
    """A length field changed to petabytes, in a file without the data section's CRC to catch it first."""
    import struct

    from teleprev.session import records as mr

    path = _copy(session, tmp_path, "length.mcap")
    offset, _ = _metadata_record(path, "rig")
    with open(path, "r+b") as f:
        f.seek(offset + 1)
        f.write(struct.pack("<Q", 1 << 50))
        _, summary_start, _ = mr.read_footer(f, path.stat().st_size)
        f.seek(summary_start - 4)
        f.write(b"\0\0\0\0")  # the data-end record's CRC: 0, none
    with pytest.raises(SessionError, match=r"metadata record 'rig' is damaged: 1125899906842624 bytes at byte \d+ run "
                                           r"past the end of the file"):
        with SessionReader(path) as reader:
            reader.metadata
    run = teleprev("eval", path)
    assert run.returncode == 1 and not has_traceback(run.stdout + run.stderr) and "MemoryError" not in run.stdout


def test_an_attachments_crc_is_checked_from_any_buffer():
    """An attachment record reads back from the bytes, a memoryview or a bytearray of the file (recover
    hands it a mapped file's), and one flipped bit in it is a CRC error."""
    import io
    import struct

    from mcap.writer import Writer

    from teleprev.session import records as mr

    out = io.BytesIO()
    writer = Writer(out)
    writer.start()
    writer.add_attachment(1, 2, "notes.txt", "text/plain", b"calibrated " * 50)
    writer.finish()
    data = out.getvalue()
    pos = data.index(bytes([mr.ATTACHMENT]), len(mr.MAGIC))
    end = pos + 9 + struct.unpack_from("<Q", data, pos + 1)[0]
    for buf in (data, memoryview(data), bytearray(data)):
        assert mr.parse_attachment(buf, pos + 9, end).data == b"calibrated " * 50
    damaged = bytearray(data)
    damaged[end - 30] ^= 1
    with pytest.raises(mr.McapFormatError, match="attachment CRC mismatch"):
        mr.parse_attachment(bytes(damaged), pos + 9, end)
