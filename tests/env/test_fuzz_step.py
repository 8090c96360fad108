"""Fuzzing the arguments of ``step``: random dicts of keys of assorted types to values of
assorted types (Python and numpy scalars, arrays of any shape and dtype, containers). The only
exception allowed is the documented ActionError (a ValueError and UserError); a call that
raises changes nothing. Bounded to a few seconds."""

from __future__ import annotations

from typing import Any

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import cdr_bench
from cdr_bench.errors import ActionError
from cdr_bench.gym_env import OwnshipEnv, OwnshipVectorEnv

FUZZ = settings(
    max_examples=200,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)

PAR = cdr_bench.parallel_env("marl/low-2")  # ownship_0, intruder_0, intruder_1
GYM = OwnshipEnv("low")
VEC = OwnshipVectorEnv(num_envs=3, scenario="low")
VEC.reset(seed=0)

DTYPES = ["int8", "uint8", "int64", "uint64", "float32", "float64", "bool", "object", "U3"]

numpy_scalar = st.builds(
    lambda i, dt: np.array(i).astype(dt)[()], st.integers(-3, 300), st.sampled_from(DTYPES)
)
numpy_array = st.builds(
    lambda i, dt, shape: np.full(shape, i).astype(dt),
    st.integers(-3, 30),
    st.sampled_from(DTYPES),
    st.sampled_from([(), (0,), (1,), (2,), (3,), (1, 1), (3, 1), (2, 3)]),
)
action_value = st.recursive(
    st.integers(-3, 30)
    | st.integers()
    | st.floats()
    | st.booleans()
    | st.none()
    | st.text(max_size=4)
    | st.binary(max_size=4)
    | st.complex_numbers()
    | numpy_scalar
    | numpy_array,
    lambda inner: (
        st.lists(inner, max_size=3) | st.tuples(inner) | st.dictionaries(st.text(), inner)
    ),
    max_leaves=6,
)
agent_key = (
    st.sampled_from(["ownship_0", "intruder_0", "intruder_1", "intruder_2", "ownship_1"])
    | st.text(max_size=6)
    | st.integers()
    | st.none()
    | st.tuples(st.integers())
    | st.frozensets(st.integers(), max_size=2)
)


def _assert_only_action_error(call: Any) -> bool:
    try:
        call()
    except ActionError as e:
        assert isinstance(e, ValueError) and 0 < len(str(e)) < 400
        return False
    return True


@settings(FUZZ)
@given(st.data())
def test_parallel_env_step(data):
    PAR.reset(seed=data.draw(st.integers(0, 3)))  # the same state for the same draws
    for _ in range(data.draw(st.sampled_from([0, 0, 80]))):  # some agents may have finished
        if PAR.agents:
            PAR.step(dict.fromkeys(PAR.agents, 13))
    live = list(PAR.agents)
    if not live:
        return
    actions: Any = {a: 13 for a in live if data.draw(st.booleans()) or len(live) == 1}
    actions.update(data.draw(st.dictionaries(agent_key, action_value, max_size=4)))
    if data.draw(st.integers(0, 9)) == 0:
        actions = data.draw(action_value | st.lists(st.tuples(agent_key, action_value)))
    steps = int(PAR.sim.steps[0])
    if not _assert_only_action_error(lambda: PAR.step(actions)):
        assert int(PAR.sim.steps[0]) == steps and PAR.agents == live


@settings(FUZZ)
@given(action_value)
def test_gymnasium_env_step(action):
    GYM.reset(seed=0)
    _assert_only_action_error(lambda: GYM.step(action))


@settings(FUZZ)
@given(action_value | st.lists(st.integers(-2, 30), min_size=3, max_size=3))
def test_gymnasium_vector_env_step(actions):
    _assert_only_action_error(lambda: VEC.step(actions))
