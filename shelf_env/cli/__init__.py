"""The project's command-line tools, installed as console scripts (see pyproject.toml):

- ``shelf-train`` (`shelf_env.cli.train`): resumable training on a wall-clock budget;
- ``shelf-evaluate`` (`shelf_env.cli.evaluate`): the §V evaluation protocol, resumable cell by cell;
- ``shelf-demo`` (`shelf_env.cli.demo`): watch a policy sort one unseen cabinet, as a GIF.
"""
