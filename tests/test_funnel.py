"""The funnel (picopit.funnel): scenes → first contact → reversed → success, and the losses
by stage, cause and who failed, on episodes whose outcomes are known."""

from __future__ import annotations

from picopit import funnel


def ep(**kw):
    base = {"success": False, "cause": None, "contacts": 1, "reversed_at": None, "decided_at": 10.0,
            "failed_vehicle": None, "error": None}
    base.update(kw)
    return base


ROWS = [
    # Lost before contact: the target leaves the road alone; the bullet hits parked traffic;
    # the controller gives up; an episode that could not run.
    ep(cause="boundary_violation", contacts=0, failed_vehicle="target", decided_at=3.0),
    ep(cause="secondary_collision", contacts=0, failed_vehicle="bullet", decided_at=2.0),
    ep(cause="decision_infeasible", contacts=0, decided_at=1.0),
    ep(cause="error", contacts=None, error="model file missing", decided_at=None),
    # Lost in the push: never reversed; failed before the reversal it reached later.
    ep(cause="no_termination", decided_at=12.0),
    ep(cause="boundary_violation", failed_vehicle="both", decided_at=4.0, reversed_at=5.0),
    # Lost after reversal: over the edge while rolling backwards; hit again.
    ep(cause="boundary_violation", failed_vehicle="target", reversed_at=4.0, decided_at=8.0),
    ep(cause="unsafe_rebound", reversed_at=4.0, decided_at=4.5),
    # Two successes.
    ep(success=True, reversed_at=4.0, decided_at=7.0),
    ep(success=True, reversed_at=3.5, decided_at=6.0, contacts=2),
]


def test_stage_counts_and_losses_of_known_outcomes():
    f = funnel.funnel(ROWS)
    assert (f["scenes"], f["first_contact"], f["reversed"], f["success"]) == (10, 6, 4, 2)
    lost = f["lost"]
    assert lost["before_contact"] == {
        "boundary_violation": {"target": 1},
        "secondary_collision": {"bullet": 1},
        "decision_infeasible": {"controller": 1},
        "error": {"error": 1},
    }
    assert lost["in_push"] == {"no_termination": {"none": 1}, "boundary_violation": {"both": 1}}
    assert lost["after_reversal"] == {"boundary_violation": {"target": 1}, "unsafe_rebound": {"each_other": 1}}
    # Every scene is either a success or lost in exactly one stage.
    assert f["success"] + sum(funnel.lost_total(f, s) for s in funnel.LOSSES) == f["scenes"]
    assert f["scenes"] - funnel.lost_total(f, "before_contact") == f["first_contact"]
    assert f["first_contact"] - funnel.lost_total(f, "in_push") == f["reversed"]
    assert f["reversed"] - funnel.lost_total(f, "after_reversal") == f["success"]


def test_markdown_lists_every_loss():
    md = funnel.markdown({"picopinn": funnel.funnel(ROWS)})
    assert "| picopinn | 10 | 6 | 4 | 2 | 4 | 2 | 2 |" in md
    assert "| picopinn | after reversal | unsafe rebound | each other | 1 |" in md
    assert "| picopinn | before contact | secondary collision | bullet | 1 |" in md
