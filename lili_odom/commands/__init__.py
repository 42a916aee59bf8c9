"""Sub-commands of the ``lili-odom`` console script (see ``lili_odom.cli``)."""
