"""The one sentence the phone shows and speaks for a decision (pure Python).

The app's ``statusMessage`` (``android_demo/www/js/view.js``) is the same rule; the shared test
vectors' ``status`` section (``python -m crossing_assist.testing.vectors``) holds the cases
both must agree on.
"""

from __future__ import annotations

#: Stop reasons beyond the Decider's: the model answered a frame too late (slow), audio cannot
#: play, the app is in the background, the field-of-view setting is invalid, the phone is tilted
#: too far, or held upright while unsure.
#: Each is a stop (the beacon never plays then).
STATUS_STOP = {
    "uncertain": "Stop. Not sure: scan slowly.",
    "stale": "Stop. Camera stalled.",
    # the app's stale decision when a frame came but the model answered it after the watchdog
    # period (a phone too slow for the bundle), not a stalled camera
    "slow": "Stop. The phone is too slow to guide.",
    "failed": "Stop. The model failed.",
    "audio": "Audio stopped. Tap to resume.",
    "background": "Stop. The app is in the background.",
    "fov": "Stop. The camera field of view setting is invalid.",
    # the app's "not sure" while its orientation sensor says the camera points far down or up
    # (android_demo/www/js/live.js, TiltWatch); the decision itself is the Decider's
    "tilt_down": "Stop. The phone points at the ground: raise it.",
    "tilt_up": "Stop. The phone points too high: lower it.",
    # the app's stop while its orientation sensor says the camera is rolled beyond what can be
    # levelled (geometry.MAX_GUIDED_ROLL_DEG; the frame is not given to the model)
    "rolled": "Stop. The phone is turned sideways: hold it level.",
    # the app's "not sure" that has lasted 5 s with the phone upright (live.js, SidewaysHint):
    # on held-out photographers the beacon plays twice as often with the phone held sideways
    "sideways": "Stop. Not sure: hold the phone sideways, it guides better.",
}
STRAIGHT_DEG = 7.5  # |heading| below: straight ahead
SLIGHT_DEG = 22.5  # below: bear slightly; at or above: turn


def status_message(stop: bool, reason: str, heading_deg: float | None) -> tuple[str, str]:
    """The one sentence the phone shows and speaks for a decision, and its style
    (``stop``/``go``): the stop reason, or the direction by |heading| (< 7.5 straight ahead,
    < 22.5 bear slightly, else turn; negative = left)."""
    if stop or heading_deg is None:
        return STATUS_STOP.get(reason, STATUS_STOP["uncertain"]), "stop"
    side = "left" if heading_deg < 0 else "right"
    if abs(heading_deg) < STRAIGHT_DEG:
        return "Go straight ahead.", "go"
    if abs(heading_deg) < SLIGHT_DEG:
        return f"Bear slightly {side}.", "go"
    return f"Turn {side}.", "go"
