"""Experiments that led nowhere (yet), kept reproducible: they may import the product (``shelf_env``,
``sb3_pixeldqn``); the product never imports them. Not installed: run from the repository root
(``python -m research.<module>``). Their pages are in docs/experiments/.
"""
