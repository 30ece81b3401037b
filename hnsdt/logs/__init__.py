"""Episode recordings: rerun (.rrd) and Foxglove-readable MCAP, from evaluation episodes or dataset episodes."""

from hnsdt.logs.record import EpisodeRecord, record_from_dataset, record_from_episode
from hnsdt.logs.mcap_log import LAYOUT_NAME, episode_layout, write_layout, write_mcap
from hnsdt.logs.rerun_log import write_rrd

__all__ = ["LAYOUT_NAME", "EpisodeRecord", "episode_layout", "record_from_dataset", "record_from_episode",
           "write_layout", "write_mcap", "write_rrd"]
