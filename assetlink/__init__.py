"""The daemons' shared client runtime: the resilient link to the server, its on-disk outbox, the
conversation over one socket, the command dispatcher, authentication over HTTP and the encrypted
asset configuration file (which the server writes and the daemons read).

Wire models live in `protocol`; this package is what a daemon runs on top of them.
"""
