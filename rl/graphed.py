"""PPO's minibatch step as a CUDA graph, where the learner is on a GPU (issue 56).

On a GPU DeepRacer's default update is launch-bound: a minibatch of 64 frames through two small
networks forward and back, clipped and stepped by Adam, is hundreds of small kernels, each
launched from Python. Captured once as a CUDA graph and replayed for every full minibatch, the
step costs 0.23 ms a step of the rollout against 1.25 on the H200 machine (docs/benchmarks.md,
"On a GPU"). PyTorch's recipe for a whole network (torch.cuda.graphs' "whole network capture"):
fixed input tensors that each minibatch is copied into, a fused, capturable Adam (its step count
on the GPU), warm-up steps on a side stream before the capture. The gradients are zeroed in place
within the step, so the graph, a warm-up and an eager step all leave the same gradients.

What stays as in the eager step: the same minibatches from the same shuffles, the same loss
(``DeepRacerPPO._loss``), the gradient clip, the learning rate. The warm-up's steps are undone, so
the first update starts from exactly the weights and optimiser state it had. A minibatch of
another size (the last of an epoch, where the rollout does not divide) is stepped eagerly on the
same gradients and optimiser. The graph is captured again when what it baked in changes (the
learning rate, the clip range, the coefficients, the precision).
"""

from __future__ import annotations

from collections.abc import Callable

import torch

Step = Callable[[], None]
Capture = Callable[[Step], Step]
"""Turns a step into its replay: ``cuda_capture`` on a GPU; a test on the CPU passes one that
returns the step itself, to check everything around the capture against the eager update."""

WARM_UP_STEPS = 3  # before the capture, on a side stream, as torch.cuda.graph asks


def cuda_capture(step: Step) -> Step:
    """``step``, warmed up on a side stream and captured as a CUDA graph: its replay."""
    side = torch.cuda.Stream()
    side.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(side):
        for _ in range(WARM_UP_STEPS):
            step()
    torch.cuda.current_stream().wait_stream(side)
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.graph(graph, capture_error_mode="thread_local"):  # the thread's work only
        step()
    return graph.replay


def batch_tensors(batch) -> list[torch.Tensor]:
    """A minibatch's tensors (PPO's ``DictRolloutBufferSamples``, SAC's batch), in a fixed order."""
    return [
        tensor
        for field in batch
        if field is not None
        for tensor in (field.values() if isinstance(field, dict) else [field])
    ]


class GraphedStep:
    """PPO's minibatch step for ``model`` (a ``DeepRacerPPO``), replayed from a graph made by
    ``capture`` for minibatches of ``model.batch_size``; ``step(batch)`` returns the minibatch's
    loss terms (policy, value, entropy), as the eager step's."""

    def __init__(self, model, capture: Capture = cuda_capture) -> None:
        self.model = model
        self.capture = capture
        self.replay: Step | None = None
        self.baked: tuple | None = None  # what the graph was captured with (``_baked``)
        self.inputs = None  # the fixed minibatch the graph reads
        self.terms: torch.Tensor | None = None  # and the loss terms it writes
        # Distributions' argument checks read a tensor back to the host, which a capture forbids;
        # the process's default, as torch keeps no other (the actions are the cars' own).
        torch.distributions.Distribution.set_default_validate_args(False)
        if model.target_kl is not None:  # it would read the KL back before every step
            raise ValueError("a graphed PPO step cannot stop at a target KL")
        policy = model.policy
        old = policy.optimizer
        if old.state:  # loading it would take the new one's fused and capturable away
            raise ValueError("a graphed PPO step takes a fresh optimiser, before any update")
        group = old.param_groups[0]
        policy.optimizer = torch.optim.Adam(
            policy.parameters(),
            lr=group["lr"],
            betas=group["betas"],
            eps=group["eps"],
            weight_decay=group["weight_decay"],
            fused=True,
            capturable=True,
        )

    def step(self, batch) -> torch.Tensor:
        model = self.model
        if len(batch.advantages) != model.batch_size:
            return self._eager(batch)
        if self.replay is None or self.baked != self._baked():
            self._capture(batch)
        torch._foreach_copy_(batch_tensors(self.inputs), batch_tensors(batch))
        self.replay()
        return self.terms.clone()

    def _baked(self) -> tuple:
        """What a capture bakes into the graph as plain numbers."""
        model = self.model
        extractor = model.policy.features_extractor
        return (
            model.policy.optimizer.param_groups[0]["lr"],
            model.clip_range(model._current_progress_remaining),
            model.ent_coef,
            model.vf_coef,
            model.max_grad_norm,
            getattr(extractor, "precision", None),
        )

    def _capture(self, batch) -> None:
        """Capture the step on a copy of ``batch``, then undo the warm-up's steps."""
        model, policy = self.model, self.model.policy
        self.inputs = type(batch)(
            *(
                {name: t.clone() for name, t in field.items()}
                if isinstance(field, dict)
                else field.clone()
                for field in batch
            )
        )
        kept = _Snapshot(policy)

        def graphed() -> None:
            # the same gradient tensors, always: the graph reads and writes them where they
            # are, so nothing may set them to None (zero_grad's default) while it lives
            policy.optimizer.zero_grad(set_to_none=False)
            loss, terms, _ = model._loss(self.inputs)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(policy.parameters(), model.max_grad_norm)
            policy.optimizer.step()
            self.terms = terms

        self.replay = self.capture(graphed)
        kept.restore()
        self.baked = self._baked()

    def _eager(self, batch) -> torch.Tensor:
        """A minibatch of another size, stepped eagerly on the graph's gradients and optimiser."""
        model, policy = self.model, self.model.policy
        policy.optimizer.zero_grad(set_to_none=False)  # the graph's gradient tensors stay
        loss, terms, _ = model._loss(batch)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(policy.parameters(), model.max_grad_norm)
        policy.optimizer.step()
        return terms


class _Snapshot:
    """The policy's weights and its optimiser's state, put back in place (the same tensors, which
    a graph captured after reads) once the warm-up has stepped them."""

    def __init__(self, policy) -> None:
        self.policy = policy
        self.weights = [p.detach().clone() for p in policy.parameters()]
        optimizer = policy.optimizer
        self.state = {
            p: {key: value.clone() for key, value in optimizer.state[p].items()}
            for p in policy.parameters()
            if p in optimizer.state
        }

    def restore(self) -> None:
        optimizer = self.policy.optimizer
        with torch.no_grad():
            for parameter, kept in zip(self.policy.parameters(), self.weights, strict=True):
                parameter.copy_(kept)
            for parameter, state in optimizer.state.items():
                kept = self.state.get(parameter)
                for key, value in state.items():
                    # a fresh optimiser's state is zero moments at step 0, as Adam makes it
                    value.copy_(kept[key]) if kept is not None else value.zero_()
