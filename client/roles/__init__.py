"""The processes of the client side, one module each (``rhbl teacher``, ``rhbl learner``,
``rhbl controller``, ``rhbl console``; the keyboard teleop of ``rhbl teacher --policy
keyboard``): their arguments, ``main`` and their process class, built on the client library
(``client.player``), label delivery (``client.labels``) and what the roles share
(``client.roles.common``)."""
