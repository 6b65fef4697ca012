"""What the two training scripts share: device choice, the torch version of mlp.MLP, and the CPN's
probabilities in torch. Imports torch: only the training commands load this module.
"""

from __future__ import annotations

import numpy as np
import torch

from teleprev.noncollision.mlp import MLP, ModelInfo


def pick_device(device: str = "auto") -> torch.device:
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(device)


def seed_everything(seed: int) -> torch.Generator:
    torch.manual_seed(seed)
    return torch.Generator().manual_seed(seed)


_ACT = {"silu": torch.nn.functional.silu, "relu": torch.relu, "tanh": torch.tanh}


class TorchMLP(torch.nn.Module):
    """Same layout and arithmetic as mlp.MLP: G parallel MLPs on padded input groups, raw output slots."""

    def __init__(self, info: ModelInfo):
        super().__init__()
        self.info = info
        self.register_buffer("offset", torch.as_tensor(info.input_offset, dtype=torch.float32))
        self.register_buffer("inv_scale", torch.as_tensor(1.0 / info.input_scale, dtype=torch.float32))
        self.register_buffer("index", torch.as_tensor(info.input_index(), dtype=torch.long))
        self.register_buffer("slot_matrix", torch.as_tensor(info.slot_matrix()))
        self.weights = torch.nn.ParameterList()
        self.biases = torch.nn.ParameterList()
        for g, a, b in info.layer_shapes():
            bound = 1.0 / a ** 0.5  # torch.nn.Linear's default initialisation, per group
            self.weights.append(torch.nn.Parameter(torch.empty(g, a, b).uniform_(-bound, bound)))
            self.biases.append(torch.nn.Parameter(torch.empty(g, 1, b).uniform_(-bound, bound)))
        self.act = _ACT[info.activation]

    def slots(self, q: torch.Tensor) -> torch.Tensor:
        x = (q - self.offset) * self.inv_scale
        x = torch.cat([x, x.new_zeros(len(x), 1)], dim=1)
        h = x[:, self.index].transpose(0, 1)  # (G, N, width_in)
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            h = torch.baddbmm(b, h, w)
            if i < last:
                h = self.act(h)
        return h.transpose(0, 1).reshape(len(q), -1)

    def outputs(self, q: torch.Tensor) -> torch.Tensor:
        """Identity combination: one value per output (the CCN's correction, or a plain CPN's logits)."""
        return self.slots(q) @ self.slot_matrix

    def cpn_log_probs(self, q: torch.Tensor, slots: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """(log p, log(1 - p)) per link for a CPN, either combination (`slots`: self.slots(q) if already known)."""
        slots = self.slots(q) if slots is None else slots
        if self.info.combine == "noisy_or":
            s = torch.nn.functional.softplus(slots) @ self.slot_matrix
            return torch.log(-torch.expm1(-s.clamp(min=1e-7))), -s
        logits = slots @ self.slot_matrix
        return torch.nn.functional.logsigmoid(logits), torch.nn.functional.logsigmoid(-logits)

    def cpn_prob(self, q: torch.Tensor) -> torch.Tensor:
        if self.info.combine == "noisy_or":
            return -torch.expm1(-(torch.nn.functional.softplus(self.slots(q)) @ self.slot_matrix))
        return torch.sigmoid(self.outputs(q))

    def to_numpy(self, info: ModelInfo | None = None) -> MLP:
        weights = [w.detach().cpu().numpy().astype(np.float32) for w in self.weights]
        biases = [b.detach().cpu().numpy()[:, 0, :].astype(np.float32) for b in self.biases]
        return MLP(info or self.info, weights, biases)

    @staticmethod
    def from_numpy(net: MLP) -> TorchMLP:
        module = TorchMLP(net.info)
        with torch.no_grad():
            for w, b, wn, bn in zip(module.weights, module.biases, net.w, net.b):
                w.copy_(torch.as_tensor(wn))
                b.copy_(torch.as_tensor(bn))
        return module
