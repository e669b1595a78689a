"""The simulated GNSS base receiver: RTCM3 (1005, MSM4/MSM7 GPS+Galileo, 1230) over TCP."""

from sim.gnss.control import gnss_router
from sim.gnss.part import GnssPart
from sim.gnss.receiver import ClientStats, GnssFaults, GnssReceiver, running_receiver
from sim.gnss.station import BaseStationModel, GnssConfig

__all__ = [
    "BaseStationModel",
    "ClientStats",
    "GnssConfig",
    "GnssFaults",
    "GnssPart",
    "GnssReceiver",
    "gnss_router",
    "running_receiver",
]
