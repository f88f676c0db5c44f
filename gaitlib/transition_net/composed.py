"""A transition-net made of parts: plain nets, each with its own gaits, each serving a set of ordered pairs.

``gaitlib fit --extend`` grows a library's switching models by the pairs of new data only: the net fitted before
keeps serving the pairs it was fitted on, with its weights as they were, and a net fitted on the new data serves the
new pairs. A plain net cannot take the grown library's inputs (its one-hot blocks are as wide as its own gait list),
so :class:`ComposedNet` takes inputs over the union of the parts' gaits (:attr:`ComposedNet.spec`) and routes each
row to the part that serves its pair: m and n are read off the row's two one-hot blocks and one-hot encoded again
over the part's gaits; the rest of the row (psi_m and phi_n, the phases, or the explicit state and phi_n) is laid
out alike for every net of one input kind and latent size, so it is passed on as it is. A pair's score is exactly
the score its part gives it.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

import torch

from gaitlib.errors import TransitionDataError
from gaitlib.transition_net.features import FeatureSpec, build_features
from gaitlib.transition_net.model import TransitionNet

__all__ = ["ComposedNet"]


class ComposedNet(torch.nn.Module):
    """Success logits of switches, each from the part (a :class:`TransitionNet`) that serves its ordered pair.

    ``parts[k]`` serves the ordered pairs ``pairs[k]`` (gait names, each a gait of that part; no pair served twice);
    ``gaits`` is the order of the inputs' one-hot blocks, holding every part's gaits. Parts must share the input kind
    and latent size. A row of a pair no part serves is refused (:class:`~gaitlib.errors.TransitionDataError`), never
    scored by a part that was not fitted on it.
    """

    def __init__(self, parts: Sequence[TransitionNet], *, pairs: Sequence[Collection[tuple[str, str]]],
                 gaits: Sequence[str]) -> None:
        super().__init__()
        if not parts or len(parts) != len(pairs):
            raise TransitionDataError(f"a composite transition-net needs one set of pairs per part, and at least one "
                                      f"part: got {len(parts)} parts and {len(pairs)} sets")
        first = parts[0].spec
        for part in parts:
            if (part.spec.kind, part.spec.latent_dim) != (first.kind, first.latent_dim):
                raise TransitionDataError(
                    f"the parts of a composite transition-net must share one input kind and latent size: "
                    f"'{first.kind}' with L={first.latent_dim} and '{part.spec.kind}' with L={part.spec.latent_dim}")
        gaits = tuple(gaits)
        self.spec = FeatureSpec(kind=first.kind, gaits=gaits, latent_dim=first.latent_dim)
        self.parts = torch.nn.ModuleList(parts)
        self.pairs = tuple(frozenset(served) for served in pairs)
        """The ordered pairs (names) each part serves."""
        g = len(gaits)
        part_of = torch.full((g, g), -1, dtype=torch.long)
        index = torch.full((len(parts), g), -1, dtype=torch.long)
        for k, (part, served) in enumerate(zip(parts, self.pairs, strict=True)):
            missing = [name for name in part.spec.gaits if name not in gaits]
            if missing:
                raise TransitionDataError(f"part {k + 1} of the composite transition-net has gaits {missing} that the "
                                          f"composite's {list(gaits)} lack")
            for i, name in enumerate(part.spec.gaits):
                index[k, gaits.index(name)] = i
            for m, n in sorted(served):
                if m not in part.spec.gaits or n not in part.spec.gaits or m == n:
                    raise TransitionDataError(f"part {k + 1} of the composite transition-net serves pair {m}-{n}, not "
                                              f"an ordered pair of its gaits {list(part.spec.gaits)}")
                cell = part_of[gaits.index(m), gaits.index(n)]
                if cell >= 0:
                    raise TransitionDataError(f"pair {m}-{n} is served by parts {int(cell) + 1} and {k + 1} of the "
                                              "composite transition-net; a pair has one part")
                part_of[gaits.index(m), gaits.index(n)] = k
        self.register_buffer("part_of", part_of, persistent=False)  # (G, G): the part serving m -> n, or -1
        self.register_buffer("part_index", index, persistent=False)  # (K, G): a gait's index in each part, or -1

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """(N,) success logits of raw inputs (N, spec.dim), each row by the part that serves its pair."""
        g = len(self.spec.gaits)
        blocks = features[:, :g], features[:, g:2 * g]
        m, n = (block.argmax(-1) for block in blocks)
        for block, code in zip(blocks, (m, n), strict=True):
            if not torch.equal(block, torch.nn.functional.one_hot(code, g).to(block.dtype)):
                raise TransitionDataError("inputs of the composite transition-net must start with one-hot m and n")
        part_of = self.part_of[m, n]
        if (part_of < 0).any():
            rows = torch.nonzero(part_of < 0).squeeze(-1).tolist()
            unserved = sorted({f"{self.spec.gaits[m[r]]}-{self.spec.gaits[n[r]]}" for r in rows})
            raise TransitionDataError(f"no part of the composite transition-net was fitted on pair(s) "
                                      f"{', '.join(unserved)}; collect them and run gaitlib fit --extend")
        rest = features[:, 2 * g:]
        logits = features.new_empty(len(features))
        for k, part in enumerate(self.parts):
            rows = torch.nonzero(part_of == k).squeeze(-1)
            if len(rows) == 0:
                continue
            width, index = len(part.spec.gaits), self.part_index[k]
            inputs = [torch.nn.functional.one_hot(index[code[rows]], width).to(features.dtype) for code in (m, n)]
            logits[rows] = part(torch.cat([*inputs, rest[rows]], dim=-1))
        return logits

    @torch.inference_mode()
    def probability(self, features: torch.Tensor) -> torch.Tensor:
        """(N,) success probability in [0, 1] of inputs (N, spec.dim); switches the module to eval mode."""
        self.eval()
        return torch.sigmoid(self(features))

    def score(self, **inputs: torch.Tensor) -> torch.Tensor:
        """(N,) success probability from named inputs, as :meth:`TransitionNet.score` takes them."""
        return self.probability(build_features(self.spec, **inputs).to(self.part_of.device))
