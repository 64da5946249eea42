"""What one consistency check found: the decision and the sentence that says it."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

logger = logging.getLogger(__name__)

#: what a check may decide
KEPT, CORRECTED, REFUSED, UNDECIDED = "kept", "corrected", "refused", "undecided"


@dataclass
class Finding:
    """One check's outcome.

    Attributes
    ----------
    check : str
        ``clock``, ``mounting``, ``wheel sign``, ``twist sign``, ``twist frame`` or ``scale``.
    sensor : str
        The stream concerned (``imu``, ``wheel``, ``odom``, ``camera``).
    decision : str
        ``kept`` (the data agree with the files; no sentence), ``corrected`` (the data contradict the files
        and say what is right: used), ``refused`` (contradicted, but ambiguous: the stream is left out) or
        ``undecided`` (the data cannot decide: the stream is used as stated, with a warning).
    sentence : str
        One plain sentence naming the file and the key to change (empty when kept).
    estimate : dict
        The figures behind the decision (JSON-friendly numbers), for ``summary.json``.
    """

    check: str
    sensor: str
    decision: str
    sentence: str = ""
    estimate: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {"check": self.check, "sensor": self.sensor, "decision": self.decision, "sentence": self.sentence,
                "estimate": dict(self.estimate)}

    def log(self) -> None:
        """The sentence in the log (the run prints it among its notes)."""
        if self.sentence:
            logger.info("%s", self.sentence)
