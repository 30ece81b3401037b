"""Episode recordings: rerun (.rrd) and Foxglove-readable MCAP, from evaluation episodes or dataset episodes."""

from hnsdt.logs.record import EpisodeRecord, record_from_dataset, record_from_episode
from hnsdt.logs.mcap_log import LAYOUT_NAME, episode_layout, mcap_bytes, write_layout, write_mcap
from hnsdt.logs.rerun_log import rrd_bytes, write_rrd


def recording_files(rec: EpisodeRecord, episode_index: int = 0) -> dict[str, bytes]:
    """The episode's ``.rrd`` and ``.mcap`` files, as bytes by suffix (encoded in memory), so that a worker of any
    executor (another process, another machine) can make them and hand them back beside its results."""
    return {".rrd": rrd_bytes(rec, episode_index), ".mcap": mcap_bytes(rec)}


__all__ = ["LAYOUT_NAME", "EpisodeRecord", "episode_layout", "mcap_bytes", "record_from_dataset",
           "record_from_episode", "recording_files", "rrd_bytes", "write_layout", "write_mcap", "write_rrd"]
