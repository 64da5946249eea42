"""Recordings: the sequence folder layout (EuRoC/ASL style plus wheel encoders), read lazily.

See ``datasets/README.md`` for the layout. :class:`Recording` opens a folder and gives each stream on
demand; camera frames are decoded one at a time while iterating, so a long recording is never held in
memory.
"""

from fusion_vo.recording.reader import Frame, Recording, write_tum

__all__ = ["Frame", "Recording", "write_tum"]
