"""`aerobase demo`: the whole platform on one machine, one real autonomous mission, then keeps serving.

`run` is the entry point and the order of things; `processes` starts and stops the child
processes; `fleet` walks the public API (organisation, users, assets, mission, schedule) and
watches the run; `daemons` writes the daemons' configuration files.
"""
