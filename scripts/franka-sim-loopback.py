#!/usr/bin/env python3
"""franka-sim's single-arm FCI server, bound to loopback on a free port.

`run-franka-sim-server` binds 0.0.0.0 on a fixed port; tests need neither. This
starts the same server (franka_sim.FrankaSimServer, both enforcement options on
unless told otherwise) on 127.0.0.1, lets the kernel pick the port (port 0), and
prints one line `FRANKA_SIM_PORT=<port>` on stdout once it listens, for the test
harness to read. The FR3 model comes from $FR3_MJCF (rigs/fr3/fr3_nomesh.xml),
so nothing is downloaded.

Where franka-sim differs from the FCI's documentation, this follows the documentation:
a command that missed its cycle is dropped, not applied (`--apply-late` restores
franka-sim's way). And it keeps the server's threads on time on a small host (below).

With `--record PATH` (or $FRANKA_SIM_RECORD) it writes down, one line each, what the
test harness judges the driver by (tests/fcisim/record.rs reads it):

    c ID ON_TIME O_T_EE_c[16] q[7]   a command answering state ID (ON_TIME 1: in its cycle)
    f ID O_T_EE_c[16] q[7]           the command that finished a motion
    j ID ON_TIME q_c[7] q[7]         the same two of a joint-position motion
    k ID q_c[7] q[7]
    l ID                             state ID's cycle closed with no answer (a lost cycle)
    a ID REASON...                   the motion aborted while state ID was the latest out
    n                                a new connection (its state ids start again)

`q` is the measured joints when the command arrived (the seed the harness solves the
commanded pose's joints from).

As a robot does (and franka-sim does not), a robot in reflex refuses every setter
(collision behaviour, impedances, end effector, load) with CommandNotPossibleRejected
until AutomaticErrorRecovery. `--reflex-on-connect N` puts the Nth connection's robot in
the reflex a client that died mid-motion leaves (communication_constraints_violation):
franka-sim starts every connection fresh and idle, a robot does not.

    FR3_MJCF=rigs/fr3/fr3_nomesh.xml python3 scripts/franka-sim-loopback.py --record cmds.txt
"""
import argparse
import logging
import os
import sys
import threading

# franka-sim stands in for a controller with a hard 1 kHz cycle, in one Python process
# whose threads (physics, state publishing, command receipt) share the GIL. Two of
# CPython's and numpy's defaults cost it the cycle on a 2-core host:
# - OpenBLAS's worker thread spins between the 7x7 solves of the simulator's inverse
#   kinematics (73 % of a core seen); one thread does them without it.
# - A thread that computes holds the GIL for up to 5 ms before it must hand over, five
#   cycles for the thread that reads commands (read up to 11 ms late); 0.2 ms instead.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.setswitchinterval(0.0002)

import struct  # noqa: E402

from franka_sim import FrankaSimServer  # noqa: E402 (after the thread settings above)
from franka_sim.comm_constraints import COMMUNICATION_CONSTRAINTS_VIOLATION_INDEX  # noqa: E402
from franka_sim.franka_protocol import LibfrankaMotionGeneratorMode  # noqa: E402
from franka_sim.franka_protocol import MessageHeader  # noqa: E402
from franka_sim.server.constants import RobotMode  # noqa: E402

#: The setters a robot in reflex refuses (franka-sim's handler names).
SETTERS = [
    "handle_set_collision_behavior_command",
    "handle_set_joint_impedance_command",
    "handle_set_cartesian_impedance_command",
    "handle_set_guiding_mode_command",
    "handle_set_ee_to_k_command",
    "handle_set_ne_to_ee_command",
    "handle_set_load_command",
]

#: GetterSetterStatus::kCommandNotPossibleRejected (libfranka's service types).
COMMAND_NOT_POSSIBLE_REJECTED = 1

log = logging.getLogger("franka-sim-loopback")


class Recorder:
    """The record --record asks for; written from the UDP and publish threads, so one
    lock. Flushed at every motion's end and abort (the harness reads it then), and
    every 1 000 lines."""

    def __init__(self, path):
        self._file = open(path, "w", buffering=1 << 20)
        self._lock = threading.Lock()
        self._lines = 0

    def line(self, text, flush=False):
        with self._lock:
            self._file.write(text + "\n")
            self._lines += 1
            if flush or self._lines % 1000 == 0:
                self._file.flush()

    @staticmethod
    def numbers(values):
        return " ".join(repr(float(v)) for v in values)


class LoopbackServer(FrankaSimServer):
    #: Whether a command that missed its cycle is dropped, as the FCI does
    #: (main sets it from --apply-late).
    drop_late = True
    #: The record (main sets it from --record), or None.
    recorder = None
    #: The connection (1-based) that finds the robot in reflex (main sets it from
    #: --reflex-on-connect), or 0.
    reflex_on_connect = 0

    _connections = 0
    _new_connection = False

    def handle_client(self, client_socket):
        # franka-sim's handle_client resets the session's state first: that reset is
        # the new connection's.
        LoopbackServer._connections += 1
        self._new_connection = True
        return super().handle_client(client_socket)

    def reset_state(self):
        super().reset_state()
        if not self._new_connection:
            return
        self._new_connection = False
        if self._connections == self.reflex_on_connect:
            state = self.robot_state.state
            state["errors"][COMMUNICATION_CONSTRAINTS_VIOLATION_INDEX] = True
            state["reflex_reason"][COMMUNICATION_CONSTRAINTS_VIOLATION_INDEX] = True
            state["robot_mode"] = RobotMode.kReflex
            log.warning("connection %s: the robot is in reflex (communication_constraints_violation), "
                        "as a client that died mid-motion leaves it", self._connections)

    # The communication tracker is replaced at every connection; each one's cycle
    # accounting is wrapped so that a lost cycle is recorded.
    @property
    def comm(self):
        return self._comm

    @comm.setter
    def comm(self, tracker):
        recorder = self.recorder
        if recorder is not None:
            tick = tracker.tick

            def recording_tick(published_id):
                outcome = tick(published_id)
                if outcome.active and outcome.lost:
                    recorder.line(f"l {outcome.closed_id}")
                return outcome

            tracker.tick = recording_tick
            recorder.line("n")
        self._comm = tracker

    def _record_command(self, kind, command, fresh=None):
        if self.recorder is None:
            return
        q = self.robot_state.state["q"]
        on_time = "" if fresh is None else (" 1" if fresh else " 0")
        # A joint-position motion commands q_c; its O_T_EE_c means nothing.
        if self.robot_state.state["motion_generator_mode"] == LibfrankaMotionGeneratorMode.kJointPosition:
            kind = {"c": "j", "f": "k"}[kind]
            commanded = command["q_c"]
        else:
            commanded = command["O_T_EE_c"]
        self.recorder.line(
            f"{kind} {command['message_id']}{on_time} "
            f"{Recorder.numbers(commanded)} {Recorder.numbers(q)}",
            flush=kind in ("f", "k"),
        )

    def _finish_motion(self, command):
        self._record_command("f", command)
        return super()._finish_motion(command)

    def _abort_with_error(self, error_index, reason, motion_id=0):
        if self.recorder is not None:
            published = self.robot_state.state["message_id"]
            self.recorder.line(f"a {published} {' '.join(str(reason).split())}", flush=True)
        return super()._abort_with_error(error_index, reason, motion_id)

    def _absorb_within_motion_limits(self, command, *, fresh):
        self._record_command("c", command, fresh)
        # "The FCI drops a command that misses its 1 ms window; the cycle is lost, the
        # extrapolation stands, and the packet never existed" (franka-sim's own
        # MotionLimitChecker.rewind_extrapolation, after libfranka's docs/overview.rst).
        # franka-sim applies it instead, for scripted clients that cannot keep the
        # cycle, and then differences the next command over the uneven interval that
        # leaves: a client on its plan, whose late command equalled the extrapolation,
        # read as 5500-9300 rad/s^3 of jerk and was aborted. A 1 kHz client is what the
        # FCI serves, so the harness drops it; the cycle still counts as lost.
        if self.drop_late and not fresh:
            log.warning(
                "dropped the command answering state %s: it came after the next state "
                "went out (the FCI drops it; the extrapolation stands)",
                command.get("message_id"),
            )
            return False
        return super()._absorb_within_motion_limits(command, fresh=fresh)

    def _bind_listener(self):
        super()._bind_listener()
        self.port = self.server_socket.getsockname()[1]
        print(f"FRANKA_SIM_PORT={self.port}", flush=True)


def _refused_in_reflex(name):
    original = getattr(FrankaSimServer, name)

    def handler(self, client_socket, header, payload):
        if self.robot_state.state["robot_mode"] == RobotMode.kReflex:
            log.warning("%s refused: the robot is in reflex (recover it first)", name)
            response = MessageHeader(header.command, header.command_id, 12 + 4).to_bytes()
            self._send_tcp(client_socket, response + struct.pack("<B3x", COMMAND_NOT_POSSIBLE_REJECTED))
            return
        return original(self, client_socket, header, payload)

    return handler


for _name in SETTERS:
    setattr(LoopbackServer, _name, _refused_in_reflex(_name))


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--port", type=int, default=0, help="TCP command port (default 0: a free one)")
    p.add_argument("--no-enforce", action="store_true", help="leave the motion-limit and communication checks off")
    p.add_argument("--apply-late", action="store_true",
                   help="apply a command that missed its cycle, as franka-sim does, instead of dropping it as the FCI does")
    p.add_argument("--record", default=os.environ.get("FRANKA_SIM_RECORD"),
                   help="write every command, lost cycle and abort to this file (default $FRANKA_SIM_RECORD)")
    p.add_argument("--reflex-on-connect", type=int, default=0, metavar="N",
                   help="the Nth connection finds the robot in reflex, as a client that died mid-motion leaves it")
    args = p.parse_args()
    LoopbackServer.reflex_on_connect = args.reflex_on_connect
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    enforce = not args.no_enforce
    if args.record:
        # Before the server exists: its constructor sets the tracker the property wraps.
        LoopbackServer.recorder = Recorder(args.record)
    server = LoopbackServer(
        host="127.0.0.1",
        port=args.port,
        enable_gripper=False,
        enforce_comm_constraints=enforce,
        enforce_motion_limits=enforce,
    )
    server.drop_late = not args.apply_late
    try:
        server.start()
    except KeyboardInterrupt:
        pass
    finally:
        # run-franka-sim-server's own teardown: stop() under a watchdog.
        from franka_sim.run_server import _shutdown

        _shutdown(server)

if __name__ == "__main__":
    main()
