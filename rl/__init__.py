"""Learning, without Django: DeepRacer's networks and policies, the learner (stable-baselines3's
PPO and SAC fed from the experience buffer), the episode's codec and the job's Redis keys, and
the car's formats (TensorFlow graph and checkpoint, ONNX). It is what the sandbox child and the
trainer's inner loop import; the training app drives it."""
