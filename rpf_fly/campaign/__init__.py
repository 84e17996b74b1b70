"""The fault campaign: every fault kind injected into dry runs of a mission, each run judged on the simulated
world's truth, so a lab sees what its stack does when something breaks before a first flight (``rpf-fly campaign``,
docs/fault-campaign.md).

One job a module: `schedules` (the faults each run injects), `missions` (the missions flown and their variants),
`flights` (flying one run and recording what it left), `truth`, `owed` and `judge` (the verdict on a record),
`report` (the table and its header), `runner` (the campaigns, run after run).
"""

from __future__ import annotations

from rpf_fly.campaign.runner import CampaignError, CampaignResult, maintainers_campaign, mission_campaign

__all__ = ["CampaignError", "CampaignResult", "maintainers_campaign", "mission_campaign"]
