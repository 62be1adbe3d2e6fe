"""Fuzzing the BVH parser: whatever the bytes, it returns a clip or raises MocapEditError.

A bounded, derandomised hypothesis run (the same cases every time): mutations of a valid
file, soups of BVH tokens, and raw bytes. Each case runs under an alarm so that a hang
fails the test instead of stalling the suite.
"""
from __future__ import annotations

import os
import signal
import tempfile

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mocapedit.formats import bvh
from mocapedit.model.errors import MocapEditError

from test_bvh import GOOD

FUZZ = settings(max_examples=300, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow])

TOKENS = ["HIERARCHY", "ROOT", "JOINT", "End", "Site", "{", "}", "OFFSET", "CHANNELS", "MOTION", "Frames:",
          "Frame", "Time:", "Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation",
          "0", "1", "3", "6", "-2.5", ".5", "1e308", "1e999", "nan", "-inf", "99999999999999999999", "Hips",
          "x", "", "\t", "\u00e9", "\ufeff"]


class Hang(Exception):
    pass


def _alarm(signum, frame):
    raise Hang("the parser did not finish within 10 s")


@pytest.fixture(scope="module")
def scratch():
    with tempfile.TemporaryDirectory(prefix="bvh-fuzz-") as d:
        yield d


def _parse(scratch, data: bytes) -> None:
    path = os.path.join(scratch, "fuzz.bvh")
    with open(path, "wb") as f:
        f.write(data)
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(10)
    try:
        motion = bvh.load(path, chunk_frames=3)
        if motion.values.shape[0]:
            bvh.convert(motion, up_axis="Z", end_sites=True)
    except MocapEditError as exc:
        assert str(exc).startswith(path), str(exc)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


@st.composite
def mutated(draw):
    text = GOOD
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["delete", "insert", "replace", "duplicate", "truncate"]))
        i = draw(st.integers(0, len(text)))
        j = draw(st.integers(i, min(len(text), i + 40)))
        if kind == "delete":
            text = text[:i] + text[j:]
        elif kind == "insert":
            text = text[:i] + draw(st.sampled_from(TOKENS + [" ", "\n", "\r\n"])) + text[i:]
        elif kind == "replace":
            text = text[:i] + draw(st.text(max_size=12)) + text[j:]
        elif kind == "duplicate":
            text = text[:j] + text[i:j] + text[j:]
        else:
            text = text[:i]
    return text.encode("utf-8", "surrogatepass")


@given(mutated())
@FUZZ
def test_mutations_of_a_valid_file(scratch, data):
    _parse(scratch, data)


@given(st.lists(st.sampled_from(TOKENS + [" ", "\n", "\r\n", "\r"]), max_size=120))
@FUZZ
def test_soups_of_bvh_tokens(scratch, tokens):
    _parse(scratch, ("HIERARCHY\n" + " ".join(tokens)).encode("utf-8"))


@given(st.binary(max_size=400))
@settings(max_examples=100, deadline=None, derandomize=True, database=None)
def test_raw_bytes(scratch, data):
    _parse(scratch, data)
