"""Episode recordings: rerun (.rrd) and Foxglove-readable MCAP, from evaluation episodes or dataset episodes."""

import tempfile
from pathlib import Path

from hnsdt.logs.record import EpisodeRecord, record_from_dataset, record_from_episode
from hnsdt.logs.mcap_log import LAYOUT_NAME, episode_layout, write_layout, write_mcap
from hnsdt.logs.rerun_log import write_rrd


def recording_files(rec: EpisodeRecord, episode_index: int = 0) -> dict[str, bytes]:
    """The episode's ``.rrd`` and ``.mcap`` files, as bytes by suffix: written in a temporary folder of the
    system's and read back, so that a worker of any executor (another process, another machine) can make them and
    hand them back beside its results."""
    with tempfile.TemporaryDirectory(prefix="hnsdt-recording-") as tmp:
        files = {".rrd": write_rrd(Path(tmp) / "episode.rrd", rec, episode_index=episode_index),
                 ".mcap": write_mcap(Path(tmp) / "episode.mcap", rec)}
        return {suffix: path.read_bytes() for suffix, path in files.items()}


__all__ = ["LAYOUT_NAME", "EpisodeRecord", "episode_layout", "record_from_dataset", "record_from_episode",
           "recording_files", "write_layout", "write_mcap", "write_rrd"]
