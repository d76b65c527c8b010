"""Several API servers sharing one store, one owner per robot.

- :mod:`server.ownership.keeper` — in the robot-link service: takes, renews and
  releases this server's robot leases and makes the engine drive exactly those
  robots (and fences itself when it cannot renew);
- :mod:`server.ownership.peers` — in the web server: who owns which robot,
  which servers are alive, and forwarding of E-stops and operator actions.

The rows live in the store: :mod:`server.store.ownership`.
"""
