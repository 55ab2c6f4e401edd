"""The SITL's data-link-loss failsafe (NAV_DLL_ACT / COM_DL_LOSS_T), in lockstep: no sockets
are read, the heartbeats of a ground station are fed to the endpoint's parser directly."""

from __future__ import annotations

from link_support import free_port, scenario, udp_to

from sitl.autopilot.flight_modes import LandedState, Mode
from sitl.link import SitlLink
from sitl.simulation import Simulation
from wire.dialect import mavlink as mav


def _link() -> SitlLink:
    link = SitlLink(Simulation(scenario(), autostart_route=False), [udp_to(free_port())])
    fc = link.sim.fc
    link.texts = []  # every STATUSTEXT the autopilot said (fc.events is drained by advance())
    say = fc.say
    fc.say = lambda text, severity=6: (link.texts.append(text), say(text, severity))[1]
    return link


def _heartbeat(link: SitlLink) -> None:
    enc = mav.MAVLink(None, 245, 190)  # a ground station's identity
    buf = mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3).pack(enc)
    link.endpoint.feed(link.endpoint.links[0], buf)


def _fly_to_hold(link: SitlLink, heartbeats: bool) -> None:
    fc = link.sim.fc
    assert fc.arm()[0] and fc.takeoff(3.0)[0]
    while not (fc.mode == Mode.HOLD and fc.landed_state == LandedState.IN_AIR):
        if heartbeats and link.chunks % 100 == 0:
            _heartbeat(link)
        link.advance()
        assert link.sim.t < 20.0, "take-off did not finish"


def test_heartbeats_stop_vehicle_lands_after_timeout_and_disarms() -> None:
    link = _link()
    try:
        sim, fc = link.sim, link.sim.fc
        assert link.params.lookup("NAV_DLL_ACT", -1) is not None
        link.params.set(link.params.lookup("COM_DL_LOSS_T", -1), 4.0)
        _fly_to_hold(link, heartbeats=True)
        _heartbeat(link)
        t_last = sim.t
        while fc.mode == Mode.HOLD:
            link.advance()
            assert sim.t < t_last + 10.0, "no failsafe after the heartbeats stopped"
        # Hold until COM_DL_LOSS_T after the last heartbeat (one mode tick of slack), then land.
        assert fc.mode == Mode.LAND
        assert 4.0 <= sim.t - t_last <= 4.0 + 0.05
        assert link.datalink.lost and link.datalink.losses == 1
        while fc.armed:
            link.advance()
            assert sim.t < t_last + 30.0, "landed but never disarmed"
        assert sim.on_ground and not sim.crashed
        assert "Data link lost: landing" in link.texts
    finally:
        link.close()


def test_no_failsafe_without_an_established_link_or_when_disabled() -> None:
    for established in (False, True):
        link = _link()
        try:
            if established:
                link.params.set(link.params.lookup("NAV_DLL_ACT", -1), 0.0)  # disabled
            _fly_to_hold(link, heartbeats=established)
            t0 = link.sim.t
            while link.sim.t < t0 + 15.0:
                link.advance()
            assert link.sim.fc.mode == Mode.HOLD and link.sim.fc.armed
            assert not link.datalink.lost
        finally:
            link.close()


def test_heartbeat_after_loss_rearms() -> None:
    link = _link()
    try:
        link.params.set(link.params.lookup("COM_DL_LOSS_T", -1), 2.0)
        link.params.set(link.params.lookup("NAV_DLL_ACT", -1), 1.0)  # hold only
        _fly_to_hold(link, heartbeats=True)
        _heartbeat(link)
        t0 = link.sim.t
        while not link.datalink.lost:
            link.advance()
            assert link.sim.t < t0 + 5.0
        assert link.sim.fc.mode == Mode.HOLD
        _heartbeat(link)
        assert not link.datalink.lost
        assert "Data link regained" in link.texts
    finally:
        link.close()
