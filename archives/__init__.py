"""A model's files in and out: the archives it is exported as (``exports``: the virtual model,
the car's, the ONNX graph), its logs laid out as DeepRacer's (``logs_archive``), its training
history (``history``), and an archive coming in (``imports``). They read and write training's
rows through its services and lifecycles; they never import its pages nor the workers' loops.
"""
