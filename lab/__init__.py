"""The command line (``rhbl``) and the in-process experiment lab.

``lab`` sits above ``server`` and ``client``: it is the only package allowed to import both,
because the in-process harness runs the simulator world and the client's behaviour code in one
process, without zenoh.
"""
