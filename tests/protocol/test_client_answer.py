"""The client takes as its ack only a reply that answers its own request (issue 14.5): the
same client_ref and, for an ack, the same user; a forged or misrouted reply is refused with
a clear error, and two answers that disagree are refused too. The operator's replies are
judged the same way."""

from __future__ import annotations

import pytest

from protocol import ErrorReply, OperatorReply, TaskAck, decode_operator_reply, encode
from protocol.client import ClientError, answer, new_client_ref, operator_answers


def ack(user: str = "u-1", ref: str | None = "r-1", rid: int = 5) -> bytes:
    return encode(TaskAck(request_id=rid, user_id=user, client_ref=ref))


def test_the_answer_is_the_reply_with_this_user_and_ref() -> None:
    assert answer([ack()], "u-1", "r-1") == TaskAck(request_id=5, user_id="u-1", client_ref="r-1")
    error = ErrorReply(field="x_m", message="outside", client_ref="r-1")
    assert answer([encode(error)], "u-1", "r-1") == error
    # beside a forgery, and the same answer twice (two routes): the answer
    assert answer([ack("u-2"), b"{junk", ack(), ack()], "u-1", "r-1").request_id == 5  # type: ignore[union-attr]


@pytest.mark.parametrize("replies, says", [
    ([ack(user="u-2")], "task_ack for user_id 'u-2', client_ref 'r-1'"),
    ([ack(ref="r-2")], "task_ack for user_id 'u-1', client_ref 'r-2'"),
    ([ack(ref=None)], "client_ref 'None'"),
    ([encode(ErrorReply(field="service", message="busy: x", client_ref="other"))], "error for client_ref 'other'"),
    ([b'{"kind": "evil"}'], "not a reply (kind:"),
])
def test_a_reply_that_does_not_answer_is_refused(replies: list[bytes], says: str) -> None:
    with pytest.raises(ClientError) as err:
        answer(replies, "u-1", "r-1")
    assert err.value.field == "reply"
    assert err.value.message.startswith("no reply answers the request of user_id 'u-1', client_ref 'r-1'")
    assert says in err.value.message


def test_two_different_answers_are_refused() -> None:
    with pytest.raises(ClientError, match="2 different replies answer the request") as err:
        answer([ack(rid=5), ack(rid=6)], "u-1", "r-1")
    assert err.value.field == "reply"


def test_a_forged_ref_with_control_characters_is_reported_escaped() -> None:
    with pytest.raises(ClientError) as err:
        answer([ack(ref="x\n\x1b[2J")], "u-1", "r-1")
    assert "\n" not in str(err.value) and "\x1b" not in str(err.value) and "x\\x0a\\x1b[2J" in err.value.message


def test_client_refs_are_fresh() -> None:
    refs = {new_client_ref() for _ in range(1000)}
    assert len(refs) == 1000 and all(len(r) == 16 for r in refs)


def reply(command: str = "start", ref: str | None = "r-1", message: str = "authority given") -> bytes:
    return encode(OperatorReply(command=command, accepted=True, authority="operator", phase="idle",  # type: ignore[arg-type]
                                message=message, client_ref=ref))


def test_an_operator_reply_is_judged_as_an_ack() -> None:
    # Was: the first reply that echoed the client_ref and the command was believed, so a
    # rogue queryable that read the command and answered first spoke for the service.
    assert operator_answers([reply()], "start", "r-1") == [OperatorReply(
        command="start", accepted=True, authority="operator", phase="idle", message="authority given",
        client_ref="r-1")]
    assert len(operator_answers([reply(), reply(message="forged")], "start", "r-1")) == 2  # refused by operator()
    assert len(operator_answers([reply(), reply(), b"{junk"], "start", "r-1")) == 1  # one answer, two routes
    assert operator_answers([reply(ref="r-2"), reply(command="hold"), reply(ref=None)], "start", "r-1") == []
    error = ErrorReply(field="command", message="no", client_ref="r-1")
    assert operator_answers([encode(error), reply()], "start", "r-1") == [error, decode_operator_reply(reply())]
