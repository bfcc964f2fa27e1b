"""The mission upload and download state machines, fed the autopilot's messages by hand."""

from __future__ import annotations

from pymavlink.dialects.v20 import common as M

from planner_service.service.link.upload import MissionDownload, MissionUpload, Silence
from protocol import GeoOrigin, HoverPoint, encode_path, same_mission

ITEMS = encode_path([HoverPoint(10.0, 20.0, 50.0, 3.0), HoverPoint(60.0, 20.0, 50.0, 3.0)], GeoOrigin(), "ardupilot")


def machine(retries: int = 3) -> tuple[MissionUpload, list]:
    sent: list = []
    return MissionUpload(ITEMS, sent.append, (1, 1), retries), sent


def req(seq: int, legacy: bool = False):
    cls = M.MAVLink_mission_request_message if legacy else M.MAVLink_mission_request_int_message
    return cls(255, 190, seq, M.MAV_MISSION_TYPE_MISSION)


def ack(result: int):
    return M.MAVLink_mission_ack_message(255, 190, result, M.MAV_MISSION_TYPE_MISSION)


def test_count_items_ack() -> None:
    up, sent = machine()
    up.begin()
    assert sent[0].get_type() == "MISSION_COUNT" and sent[0].count == len(ITEMS) == 5
    assert up.on_message(ack(M.MAV_MISSION_ACCEPTED)) is None  # stale ACK before any request
    for seq in range(len(ITEMS)):
        assert up.on_message(req(seq, legacy=(seq == 2))) is None  # ArduPilot's legacy request too
    done = up.on_message(ack(M.MAV_MISSION_ACCEPTED))
    assert done is not None and done.accepted and done.result == "MAV_MISSION_ACCEPTED"
    assert [m.get_type() for m in sent[1:]] == ["MISSION_ITEM_INT"] * 5
    assert [m.seq for m in sent[1:]] == [0, 1, 2, 3, 4]


def test_an_accepted_before_the_last_item_went_out_is_not_this_uploads() -> None:
    # A duplicated or late ACK of the upload before, on a lossy link, arriving once this
    # upload's first items went out: the vehicle has not got them all, so it is not ours.
    up, sent = machine()
    up.begin()
    for seq in range(len(ITEMS) - 1):
        assert up.on_message(req(seq)) is None
        assert up.on_message(ack(M.MAV_MISSION_ACCEPTED)) is None, f"stale ACCEPTED taken after item {seq}"
    assert up.on_message(req(len(ITEMS) - 1)) is None
    done = up.on_message(ack(M.MAV_MISSION_ACCEPTED))
    assert done is not None and done.accepted


def test_short_waits_repeat_sooner_but_give_up_no_sooner() -> None:
    """Ten repeats 0.1 s apart are one second: PX4 asks again for a lost item only every
    0.25 s and ignores the item we repeat meanwhile, so on a lossy link a second of silence
    is not a lost vehicle (a clean-clone run gave up so, at item 13 of 20). Giving up needs
    the repeats and the patience both; an answer starts both again."""
    now = [0.0]
    silence = Silence(retries=10, patience_s=5.0, clock=lambda: now[0])
    for _ in range(10):
        now[0] += 0.1
        assert not silence.ran_out()
    now[0] += 0.1
    assert not silence.ran_out()  # 11 waits out, but 1.1 s is short of the patience
    now[0] = 4.9
    silence.answered()
    now[0] = 10.0
    for _ in range(10):  # 5.1 s since the answer, but the repeats start again from 0
        assert not silence.ran_out()
    assert silence.ran_out() and silence.over() == " in 5.1 s"
    impatient = Silence(retries=2, patience_s=0.0, clock=lambda: now[0])
    assert [impatient.ran_out() for _ in range(3)] == [False, False, True]


def test_silence_repeats_then_gives_up() -> None:
    up, sent = machine(retries=2)
    up.begin()
    assert up.on_timeout() is None and sent[-1].get_type() == "MISSION_COUNT"
    up.on_message(req(0))
    assert up.on_timeout() is None and sent[-1].get_type() == "MISSION_ITEM_INT" and sent[-1].seq == 0
    assert up.on_timeout() is None
    done = up.on_timeout()
    assert done is not None and not done.accepted and done.result.startswith("NO_ANSWER after 2 repeats of item 0")


def test_refusal_and_bad_request() -> None:
    up, _ = machine()
    up.begin()
    up.on_message(req(0))
    done = up.on_message(ack(M.MAV_MISSION_INVALID_PARAM5_X))
    assert done is not None and not done.accepted and done.result == "MAV_MISSION_INVALID_PARAM5_X"
    up2, _ = machine()
    up2.begin()
    bad = up2.on_message(req(9))
    assert bad is not None and not bad.accepted and "BAD_REQUEST" in bad.result


def test_given_up_after_the_last_item_may_have_been_committed() -> None:
    up, _ = machine(retries=1)
    up.begin()
    for seq in range(len(ITEMS)):
        up.on_message(req(seq))
    assert up.on_timeout() is None  # the last item again
    done = up.on_timeout()
    assert done is not None and not done.accepted and done.maybe_committed
    early, _ = machine(retries=1)
    early.begin()
    early.on_message(req(0))
    early.on_timeout()
    done = early.on_timeout()
    assert done is not None and not done.maybe_committed  # the vehicle never had every item


def test_download_reads_what_the_vehicle_holds() -> None:
    sent: list = []
    down = MissionDownload(sent.append, (1, 1), retries=2)
    down.begin()
    assert sent[-1].get_type() == "MISSION_REQUEST_LIST"
    assert down.on_timeout() is None and sent[-1].get_type() == "MISSION_REQUEST_LIST"  # asked again
    assert down.on_message(M.MAVLink_mission_count_message(255, 190, len(ITEMS), M.MAV_MISSION_TYPE_MISSION)) is None
    for item in ITEMS:
        assert sent[-1].get_type() == "MISSION_REQUEST_INT" and sent[-1].seq == item.seq
        assert down.on_message(item.to_message(255, 190)) is down.done  # None until the last
        if item.seq == 1:
            assert down.on_message(item.to_message(255, 190)) is None  # a duplicate changes nothing
    done = down.done
    assert done is not None and done.ok and same_mission(list(done.items), ITEMS)
    assert sent[-1].get_type() == "MISSION_ACK" and sent[-1].type == M.MAV_MISSION_ACCEPTED


def test_download_of_nothing_refusal_and_silence() -> None:
    sent: list = []
    empty = MissionDownload(sent.append, (1, 1), retries=2)
    empty.begin()
    done = empty.on_message(M.MAVLink_mission_count_message(255, 190, 0, M.MAV_MISSION_TYPE_MISSION))
    assert done is not None and done.ok and done.items == ()
    refused = MissionDownload(sent.append, (1, 1), retries=2)
    refused.begin()
    refused.on_message(M.MAVLink_mission_count_message(255, 190, 3, M.MAV_MISSION_TYPE_MISSION))
    done = refused.on_message(ack(M.MAV_MISSION_INVALID_SEQUENCE))
    assert done is not None and not done.ok and done.result == "MAV_MISSION_INVALID_SEQUENCE"
    silent = MissionDownload(sent.append, (1, 1), retries=1)
    silent.begin()
    assert silent.on_timeout() is None
    done = silent.on_timeout()
    assert done is not None and not done.ok and done.result.startswith("NO_ANSWER after 1 requests for MISSION_COUNT in ")


def test_a_repeated_item_answered_invalid_sequence_goes_on() -> None:
    # ArduPilot answers an item it already has (our repeat crossed its next request) with
    # INVALID_SEQUENCE and asks again for the next one a second later: the upload waits.
    up, sent = machine(retries=2)
    up.begin()
    up.on_message(req(0))
    up.on_message(req(1))
    for _ in range(5):  # more repeats than the retries: each one answered
        assert up.on_timeout() is None and sent[-1].seq == 1
        assert up.on_message(ack(M.MAV_MISSION_INVALID_SEQUENCE)) is None
    for seq in range(2, len(ITEMS)):
        up.on_message(req(seq))
    done = up.on_message(ack(M.MAV_MISSION_ACCEPTED))
    assert done is not None and done.accepted


def test_error_after_the_last_item_means_the_ack_was_lost() -> None:
    # ArduPilot answers ERROR to an item after the upload ended: our repeat of the last item
    # crossed its (lost) ACCEPTED. Maybe committed: the link reads the mission back.
    up, sent = machine()
    up.begin()
    for seq in range(len(ITEMS)):
        up.on_message(req(seq))
    assert up.on_timeout() is None and sent[-1].seq == len(ITEMS) - 1
    done = up.on_message(ack(M.MAV_MISSION_ERROR))
    assert done is not None and not done.accepted and done.maybe_committed
    early, _ = machine()
    early.begin()
    early.on_message(req(0))
    done = early.on_message(ack(M.MAV_MISSION_ERROR))
    assert done is not None and not done.maybe_committed, "an ERROR before the last item is a refusal"


def test_error_after_a_stale_request_had_an_earlier_item_sent_again_may_be_committed() -> None:
    # On a lossy link a duplicated request for item 1 came late, after the last item went
    # out: item 1 went again, and PX4, its upload over, answered "IGN MISSION_ITEM: No
    # transfer" (ERROR). The vehicle had every item: the link reads the mission back.
    up, sent = machine()
    up.begin()
    for seq in range(len(ITEMS)):
        up.on_message(req(seq))
    assert up.on_message(req(1)) is None and sent[-1].seq == 1
    done = up.on_message(ack(M.MAV_MISSION_ERROR))
    assert done is not None and not done.accepted and done.maybe_committed
    silent, _ = machine(retries=1)
    silent.begin()
    for seq in range(len(ITEMS)):
        silent.on_message(req(seq))
    silent.on_message(req(1))
    assert silent.on_timeout() is None
    done = silent.on_timeout()
    assert done is not None and done.maybe_committed, "silence after the last item went out: maybe committed"
