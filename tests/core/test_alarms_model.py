"""The ISA-18.2 state machine as a table: every transition, latching and not, and what hides an alarm."""

from __future__ import annotations

import pytest

from softplc.core.alarms import AlarmState, Trigger, effective_state, next_state, released_state

N, U, A, R, L = (AlarmState.NORMAL, AlarmState.UNACKNOWLEDGED, AlarmState.ACKNOWLEDGED, AlarmState.RETURNED, AlarmState.LATCHED)
ACT, REALARM, CLEAR, ACK = Trigger.ACTIVATE, Trigger.REALARM, Trigger.CLEAR, Trigger.ACKNOWLEDGE

# (state, trigger, next when not latching, next when latching); None: the trigger changes nothing.
ISA_18_2 = [
    (N, ACT, U, U),  # the process goes abnormal: annunciated, unacknowledged
    (N, CLEAR, None, None),
    (N, ACK, None, None),  # nothing to acknowledge
    (U, ACK, A, A),
    (U, CLEAR, R, L),  # returns to normal before anyone acknowledged it
    (U, ACT, None, None),
    (U, REALARM, None, None),  # already waiting for an acknowledgement
    (A, CLEAR, N, L),  # a latching alarm stays latched until reset
    (A, REALARM, U, U),  # a more severe limit must be acknowledged again
    (A, ACK, None, None),
    (A, ACT, None, None),
    (R, ACK, N, N),
    (R, ACT, U, U),
    (R, CLEAR, None, None),
    (L, ACK, N, N),  # acknowledging a latched alarm is its reset
    (L, ACT, U, U),
    (L, CLEAR, None, None),
]


@pytest.mark.parametrize(("state", "trigger", "plain", "latching"), ISA_18_2,
                         ids=[f"{s.value}-{t.value}" for s, t, _, _ in ISA_18_2])
def test_every_isa_18_2_transition(state: AlarmState, trigger: Trigger, plain: AlarmState | None, latching: AlarmState | None) -> None:
    assert next_state(state, trigger, latching=False) is plain
    assert next_state(state, trigger, latching=True) is latching


def test_the_table_covers_every_annunciation_state_and_trigger() -> None:
    covered = {(state, trigger) for state, trigger, _, _ in ISA_18_2}
    for state in (N, U, A, R, L):
        for trigger in (ACT, CLEAR, ACK):
            assert (state, trigger) in covered, (state, trigger)


def test_out_of_service_hides_suppression_which_hides_shelving() -> None:
    assert effective_state(U, shelved=False, suppressed=False, out_of_service=False) is U
    assert effective_state(U, shelved=True, suppressed=False, out_of_service=False) is AlarmState.SHELVED
    assert effective_state(U, shelved=True, suppressed=True, out_of_service=False) is AlarmState.SUPPRESSED
    assert effective_state(U, shelved=True, suppressed=True, out_of_service=True) is AlarmState.OUT_OF_SERVICE
    assert not AlarmState.SHELVED.annunciated and not AlarmState.SHELVED.needs_acknowledgement
    assert [state for state in AlarmState if state.needs_acknowledgement] == [U, R, L]


def test_an_alarm_released_while_still_active_is_annunciated_anew() -> None:
    assert released_state(True) is U
    assert released_state(False) is N
