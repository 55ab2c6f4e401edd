"""windseek as PX4's simulator (``windseek sitl SCENARIO --px4``): PX4 flies windseek's world.

PX4 SITL connects to windseek over TCP (4560 + instance) and runs in lockstep with it; a flight
controller in HITL (``SYS_HITL 1``) talks over a serial port in real time. windseek sends the
world's sensors (HIL_SENSOR, HIL_GPS, HIL_STATE_QUATERNION) and steps the world with PX4's
actuator outputs (HIL_ACTUATOR_CONTROLS); its built-in autopilot does not fly. The chemical
reading, the rotor speeds and the truth reach the companion programs through PX4's MAVLink
forwarding, from windseek's peripheral component 158.

Modules: :mod:`~sitl.hil.motors` (motor order, thrust curve, output checks),
:mod:`~sitl.hil.messages` (message builders), :mod:`~sitl.hil.guard` (who flies: PX4 or the safety
pilot), :mod:`~sitl.hil.bridge` (the world one lockstep step at a time, no I/O),
:mod:`~sitl.hil.px4_link` (TCP server / serial port), :mod:`~sitl.hil.peripheral` (the component
that reaches the companions), :mod:`~sitl.hil.runner` (the lockstep loop),
:mod:`~sitl.hil.summary` (scores against the truth), :mod:`~sitl.hil.px4_params` (PX4's parameters
for the vehicle), :mod:`~sitl.hil.px4_process` (start and stop a PX4 SITL binary),
:mod:`~sitl.hil.launch` (the command line).
"""
