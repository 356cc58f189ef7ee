"""Metrics: estimation errors and consistency (:mod:`.errors`), multi-target track scores (:mod:`.tracks`) and
the scoring of nearest-neighbour choices (:mod:`.association`)."""

from .association import AssociationLog, association_log, coasted
from .errors import chi2_band, nees, nis, position_sq_error, rmse
from .ospa import GOSPA, OSPA, gospa, ospa, track_gospa, track_ospa, track_positions, truth_positions
from .tracks import (TrackCounts, continuity, false_track_sums, mean_std, pooled_rmse, removal_rate_pooled,
                     removal_rate_pooled_per_ping, removal_ratio, track_counts, track_truth_match)

__all__ = ["nees", "nis", "chi2_band", "position_sq_error", "rmse", "TrackCounts", "track_truth_match", "track_counts",
           "false_track_sums", "removal_ratio", "removal_rate_pooled",
           "removal_rate_pooled_per_ping", "continuity", "pooled_rmse", "mean_std", "AssociationLog",
           "association_log", "coasted", "OSPA", "GOSPA", "ospa", "gospa", "track_ospa", "track_gospa", "track_positions",
           "truth_positions"]
