#!/usr/bin/env python3
"""franka-sim's single-arm FCI server, bound to loopback on a free port.

`run-franka-sim-server` binds 0.0.0.0 on a fixed port; tests need neither. This
starts the same server (franka_sim.FrankaSimServer, both enforcement options on
unless told otherwise) on 127.0.0.1, lets the kernel pick the port (port 0), and
prints one line `FRANKA_SIM_PORT=<port>` on stdout once it listens, for the test
harness to read. The FR3 model comes from $FR3_MJCF (../shared/rigs/fr3_nomesh.xml),
so nothing is downloaded.

    FR3_MJCF=../shared/rigs/fr3_nomesh.xml python3 scripts/franka-sim-loopback.py
"""
import argparse
import logging
import sys

from franka_sim import FrankaSimServer


class LoopbackServer(FrankaSimServer):
    def _bind_listener(self):
        super()._bind_listener()
        self.port = self.server_socket.getsockname()[1]
        print(f"FRANKA_SIM_PORT={self.port}", flush=True)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--port", type=int, default=0, help="TCP command port (default 0: a free one)")
    p.add_argument("--no-enforce", action="store_true", help="leave the motion-limit and communication checks off")
    args = p.parse_args()
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    enforce = not args.no_enforce
    server = LoopbackServer(
        host="127.0.0.1",
        port=args.port,
        enable_gripper=False,
        enforce_comm_constraints=enforce,
        enforce_motion_limits=enforce,
    )
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
