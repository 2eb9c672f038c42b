"""The EN 50159 threat campaign (SPEC §9, §10): repetition, deletion, insertion, resequencing,
corruption, delay and masquerade, each injected through the tap of a running link.

Owns: the view of a running tap from outside (`wire`), the devices' state behind a link
(`application`), the threats and their verdicts (`campaign`; `ThreatTarget` is a tapped link
under attack), a small lab to attack when no target is given (`minilab`) and the reports
(`report`). Talks to taps only over their control ports, so a lab started by `lab up`, a tap
started by `tap run` and the small lab are attacked the same way.
Must not import the emulators (emulator/) nor the signalling cores (ixl/, field/, atc/): what it
knows of a device it reads over the device's control port. Nothing but cli/ imports it.
"""

from ktcs_bench.threats.application import Application, find_in_labs
from ktcs_bench.threats.campaign import THREATS, ThreatTarget, run_campaign
from ktcs_bench.threats.report import ThreatResult, markdown, summary
from ktcs_bench.threats.wire import WireTap

__all__ = ["THREATS", "Application", "ThreatTarget", "ThreatResult", "WireTap", "find_in_labs",
           "markdown", "run_campaign", "summary"]  # fmt: skip
