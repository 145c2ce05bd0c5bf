"""Torque read-back: a servo that loses torque under a running loop (a brownout reboots it, another program on the
bus switches it off) stops the motion within 0.2 s, the servos still holding torque glide to rest, torque goes off
and the error names the servo; its torque is never switched back on."""

from __future__ import annotations

import math
import time
from types import SimpleNamespace

import numpy as np
import pytest

from robogest.backends.base import get_backend_factory
from robogest.backends.control import ControlLoop
from robogest.backends.player import play
from robogest.errors import BackendError
from robogest.virtualbus import VirtualBus
from robogest.virtualbus.testing import make_robot
from tests.backends.test_servo_stop import RAISED, hold, present_rad

BUSES = [("dynamixel", 2.0), ("dynamixel", 1.0), ("feetech", 0.0)]
#: The simulated bus answers from a thread of this process, which a loaded machine can starve past the 0.15 s
#: lost-servo time; these tests are about torque found off, not about lost servos or health readings.
NOT_LOST = {"lost_after_s": 1.0, "health_hz": 0}


@pytest.mark.parametrize(("family", "protocol"), BUSES)
@pytest.mark.parametrize("fault", ["torqueoff", "reboot"])
def test_a_servo_found_limp_mid_gesture_stops_and_the_others_glide_to_rest(tmp_path, family, protocol, fault):
    robot = make_robot(tmp_path, family=family, protocol=protocol, v_max=2.0, a_max=10.0)
    with VirtualBus(robot, f"{fault}=2@0.4", start_q_rad=np.full(3, RAISED)) as bus:
        backend = get_backend_factory(family)(robot, port=bus.port, **NOT_LOST)
        with pytest.raises(BackendError, match=r"^servo id 2 \(joint j1\): torque found off while robogest held it on"):
            play(hold(robot, 2.0), backend)
        time.sleep(0.05)
        rec = bus.record()
    assert backend.limp_ids == [2]
    q = present_rad(bus, backend)
    np.testing.assert_allclose(q[[0, 2]], robot.rest_q_rad[[0, 2]], atol=0.02)  # the others went to rest
    assert abs(q[1] - RAISED) < 0.05  # the limp one stayed where it was: nothing switched its torque back on
    after = rec["t_s"] >= 0.41
    assert not rec["torque_on"][after, list(rec["servo_ids"]).index(2)].any()
    assert rec["torque_on"][after].any() and not rec["torque_on"][-1].any()


def _steps_until_error(loop: ControlLoop, limit: int) -> int:
    for k in range(1, limit + 1):
        try:
            loop.step()
        except BackendError as e:
            assert "torque found off" in str(e)
            return k
    return limit + 1


@pytest.mark.parametrize(("family", "protocol"), BUSES)
@pytest.mark.parametrize("rate_hz", [50.0, 100.0])
def test_torque_lost_at_any_tick_is_found_within_0_2_s_of_ticks(tmp_path, family, protocol, rate_hz):
    """Torque switched off before tick k (every phase of the read-back's cycle) is found by tick
    k + torque_check_ticks - 1, within ceil(0.2 s * rate); one lost read-back reply costs one tick more."""
    robot = make_robot(tmp_path, family=family, protocol=protocol)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory(family)(robot, port=bus.port, **NOT_LOST)
        loop = ControlLoop(backend, rate_hz, threaded=False).start()
        n = backend.torque_check_ticks
        bound = math.ceil(0.2 * rate_hz)
        assert n == round(0.1 * rate_hz) and n < bound
        found = []
        try:
            for phase in range(n):
                backend.set_torque(True)  # the operator puts it back on: the read-back's cycle starts again
                for _ in range(phase):
                    loop.step()
                bus.inject_now("torqueoff", 2)
                found.append(_steps_until_error(loop, bound))
            backend.set_torque(True)  # and once more, with the first read-back reply of servo 2 lost
            read = backend._sync_read_group

            def lose_servo_2(reg, ids):
                got = read(reg, ids)
                if reg is backend.REG["torque"] and not lost:
                    lost.append(ids)
                    got[2] = (0, False, 0, "no reply (timeout)")
                return got

            lost: list = []
            backend._sync_read_group = lose_servo_2
            bus.inject_now("torqueoff", 2)
            with_loss = _steps_until_error(loop, bound)
        finally:
            loop.close()
    assert max(found) <= n and with_loss <= n + 1 <= bound, (found, with_loss)


def test_torque_the_backend_turns_off_itself_is_not_taken_for_a_limp_servo(tmp_path):
    robot = make_robot(tmp_path)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory("dynamixel")(robot, port=bus.port)
        loop = ControlLoop(backend, 50.0, threaded=False).start()
        loop.run_for(0.3)
        backend.set_torque(False)
        for _ in range(3 * backend.torque_check_ticks):
            backend.read_positions()
        loop.close()
        assert backend.limp_ids == [] and not any(s.torque_on for s in bus.servos)


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf")])
def test_a_bad_torque_check_period_is_refused_naming_it(tmp_path, bad):
    from robogest.errors import InputError

    with pytest.raises(InputError, match="torque_check_s"):
        get_backend_factory("dynamixel")(make_robot(tmp_path), port="/dev/null", torque_check_s=bad)


def test_a_struggling_bus_puts_the_read_back_off_for_at_most_torque_check_s(tmp_path, monkeypatch):
    """On a tick whose position read had to re-read or missed a servo, the read-back waits (that tick already ran
    long, and two missed position reads over lost_after_s declare a servo lost), but not past torque_check_s."""
    import robogest.backends.servos.bus as sc

    robot = make_robot(tmp_path)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory("dynamixel")(robot, port=bus.port, **NOT_LOST)
        backend.connect()
        try:
            backend.set_torque(True)
            bus.inject_now("torqueoff", 2)
            n = backend.torque_check_ticks
            clock = [backend._torque_read_s]
            monkeypatch.setattr(sc, "time", SimpleNamespace(monotonic=lambda: clock[0], sleep=time.sleep))
            ticks = 0
            with pytest.raises(BackendError, match=r"servo id 2 \(joint j1\): torque found off"):
                while ticks < 10 * n:
                    ticks += 1
                    clock[0] += backend.control_period_s
                    backend._maybe_check_torque(busy=True)
        finally:
            monkeypatch.undo()
            backend.shutdown()
    assert 2 * n - 1 <= ticks <= 2 * n + 1  # put off from tick n for 0.1 s (n ticks), then read
