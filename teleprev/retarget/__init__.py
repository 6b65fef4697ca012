"""Retargeting: SMPL-X hand and wrist motion to robot joints."""
