"""The client side: the Player-like library (``client.player``: ``PlayerClient``,
``Position2dProxy``, ``LaserProxy``), pure behaviour code (``client.behaviour``) and the
teacher, learner and controller processes. Importing ``client`` loads no zenoh."""
