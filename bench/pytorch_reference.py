"""PyTorch re-statement of scbg-model's Multipath++ for a speed comparison (benchmark tool only;
scbg never needs Python at run time).

Same structure and widths as crates/model (MultipathConfig presets), same batch shapes as
`scbg bench train` (batch 32, 16 other agents, 64 road segments, 11 history steps, 80 future
steps), same loss (GMM NLL with clamped covariance parameters) and optimizer (Adam, grad-norm
clip 0.4). Prints ms per training step and inference samples/s with 2 threads; on a GPU
(`--device cuda`) each timed step ends with `torch.cuda.synchronize()`.

    pip install torch
    python3 bench/pytorch_reference.py --preset cpu-small --preset paper
    python3 bench/pytorch_reference.py --preset paper --device cuda --batch 256 --steps 20
"""
import argparse
import time

import torch
from torch import nn

PRESETS = {
    "cpu-small": dict(lstm_hidden=16, step_mlp=[16, 32], target_width=64, interaction_width=64,
                      road_mlp=[16, 32], road_context_hidden=64, decoder_width=160, decoder_hidden=128,
                      num_modes=6, mcg_blocks=2, future_hidden=64),
    "paper": dict(lstm_hidden=64, step_mlp=[32, 64, 128], target_width=256, interaction_width=256,
                  road_mlp=[32, 64, 128], road_context_hidden=256, decoder_width=640, decoder_hidden=512,
                  num_modes=6, mcg_blocks=5, future_hidden=256),
}
H, T, AGENT, DIFF, ROAD = 11, 80, 13, 11, 27


def mlp(dims):
    layers = []
    for i in range(len(dims) - 1):
        layers.append(nn.Linear(dims[i], dims[i + 1]))
        if i + 2 < len(dims):
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


def masked_max(x, mask):
    m = mask.unsqueeze(-1)
    filled = x * m + (m - 1.0) * 1e9
    return filled.max(dim=1).values * mask.max(dim=1, keepdim=True).values


class CG(nn.Module):
    def __init__(self, d):
        super().__init__()
        self.s = mlp([d, d, d, d])
        self.c = mlp([d, d, d, d])

    def forward(self, s, c, mask):
        out = self.s(s) * self.c(c).unsqueeze(1) * mask.unsqueeze(-1)
        return out, masked_max(out, mask)


class MCG(nn.Module):
    def __init__(self, d_in, d_ctx, w, n):
        super().__init__()
        self.blocks = nn.ModuleList([CG(w) for _ in range(max(n, 1))])
        self.in_s, self.in_c = nn.Linear(d_in, w), nn.Linear(d_ctx, w)

    def forward(self, s, c, mask):
        s_acc, c_acc = self.in_s(s), self.in_c(c)
        s_in, c_in = s_acc, c_acc
        for k, b in enumerate(self.blocks):
            so, co = b(s_in, c_in, mask)
            s_acc, c_acc = s_acc + so, c_acc + co
            s_in, c_in = s_acc / (k + 2), c_acc / (k + 2)
        return s_in, c_in


class History(nn.Module):
    def __init__(self, p):
        super().__init__()
        self.l1 = nn.LSTM(AGENT, p["lstm_hidden"], batch_first=True)
        self.l2 = nn.LSTM(DIFF, p["lstm_hidden"], batch_first=True)
        self.step = mlp([AGENT + H] + p["step_mlp"])
        w = p["step_mlp"][-1]
        self.mcg = MCG(w, 1, w, p["mcg_blocks"])
        self.register_buffer("eye", torch.eye(H))

    def forward(self, hist, diffs):
        n = hist.shape[0]
        _, (h1, _) = self.l1(hist)
        _, (h2, _) = self.l2(diffs)
        x = torch.cat([hist, self.eye.expand(n, H, H)], -1)
        _, summ = self.mcg(self.step(x), hist.new_ones(n, 1), hist[:, :, 6])
        return torch.cat([h1[0], h2[0], summ], 1)


class Multipath(nn.Module):
    def __init__(self, p):
        super().__init__()
        hist_out = 2 * p["lstm_hidden"] + p["step_mlp"][-1]
        rw = p["road_mlp"][-1]
        e = p["target_width"] + p["interaction_width"] + rw
        fh = p["future_hidden"]
        self.history = History(p)
        self.target = MCG(hist_out, 1, p["target_width"], p["mcg_blocks"])
        self.inter = MCG(hist_out, p["target_width"], p["interaction_width"], p["mcg_blocks"])
        self.road_mlp = mlp([ROAD] + p["road_mlp"])
        self.road_ctx = mlp([p["target_width"] + p["interaction_width"], p["road_context_hidden"], rw])
        self.road = MCG(rw, rw, rw, p["mcg_blocks"])
        self.fut = mlp([(T // 5) * 5 + p["target_width"], fh, fh, fh])
        self.fuse = nn.Linear(e + fh + 1, e)
        self.anchors = nn.Parameter(torch.randn(p["num_modes"], e))
        self.dec = MCG(e, e, p["decoder_width"], p["mcg_blocks"])
        self.dec_mlp = mlp([p["decoder_width"], p["decoder_hidden"], 5 * T + 1])
        self.mode_logits = nn.Linear(e, p["num_modes"])

    def forward(self, b):
        B, A = b["others_history"].shape[:2]
        th = self.history(b["target_history"], b["target_diffs"])
        target, _ = self.target(th.unsqueeze(1), th.new_ones(B, 1), th.new_ones(B, 1))
        target = target[:, 0]
        oh = self.history(b["others_history"].reshape(B * A, H, AGENT), b["others_diffs"].reshape(B * A, H - 1, DIFF))
        _, inter = self.inter(oh.reshape(B, A, -1), target, b["others_mask"])
        road = self.road_mlp(b["road"])
        _, road = self.road(road, self.road_ctx(torch.cat([target, inter], 1)), b["road_mask"])
        scene = torch.cat([target, inter, road], 1)
        raw, prev = b["condition"][:, 4::5], b["condition"][:, 3::5]
        both = raw[:, :, 2:3] * prev[:, :, 2:3]
        vel = (raw[:, :, :2] - prev[:, :, :2]) * both / (0.1 * 10.0)
        feats = torch.cat([raw[:, :, :2] / 50, raw[:, :, 2:3], vel], -1).reshape(B, -1)
        cond = self.fut(torch.cat([feats, target], 1))
        flag = b["flag"]
        scene = scene + self.fuse(torch.cat([scene, cond * flag, flag], 1))
        K = self.anchors.shape[0]
        modes, _ = self.dec(self.anchors.unsqueeze(0).expand(B, -1, -1), scene, scene.new_ones(B, K))
        out = self.dec_mlp(torch.relu(modes))
        xy = out[..., : 2 * T].reshape(B, K, T, 2).cumsum(2)
        abc = out[..., 2 * T: 5 * T].reshape(B, K, T, 3)
        return xy, abc, out[..., 5 * T] + self.mode_logits(scene)


def gmm_nll(xy, abc, logits, target, valid):
    d = target.unsqueeze(1) - xy
    dx, dy = d[..., 0], d[..., 1]
    a, bb, c = abc[..., 0].clamp(-2, 2), abc[..., 1].clamp(-2, 2), abc[..., 2].clamp(-2, 8)
    quad = (torch.exp(-a) * torch.cosh(bb) * dx ** 2 - 2 * torch.sinh(bb) * dx * dy
            + torch.exp(a) * torch.cosh(bb) * dy ** 2) * torch.exp(-c)
    ll = ((-0.5 * quad - c) * valid.unsqueeze(1)).sum(-1)
    return -torch.logsumexp(torch.log_softmax(logits, 1) + ll, 1).mean()


def batch(B=32, A=16, P=64, device="cpu"):
    g = torch.Generator().manual_seed(0)
    r = lambda *s: torch.randn(*s, generator=g)
    b = dict(target_history=r(B, H, AGENT), target_diffs=r(B, H - 1, DIFF),
                others_history=r(B, A, H, AGENT), others_diffs=r(B, A, H - 1, DIFF),
                others_mask=torch.ones(B, A), road=r(B, P, ROAD), road_mask=torch.ones(B, P),
                condition=torch.cat([r(B, T, 2) * 20, torch.ones(B, T, 1)], -1), flag=torch.ones(B, 1),
                future_xy=r(B, T, 2) * 10, future_valid=torch.ones(B, T))
    return {k: v.to(device) for k, v in b.items()}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--preset", action="append")
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--device", default="cpu", help="cpu or cuda")
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--warmup", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    dev = torch.device(args.device)
    sync = torch.cuda.synchronize if dev.type == "cuda" else (lambda: None)
    b = batch(args.batch, device=dev)
    where = torch.cuda.get_device_name(dev) if dev.type == "cuda" else f"{args.threads} threads"
    print(f"pytorch {torch.__version__}, {where}, batch {args.batch}, 16 other agents, 64 road segments")
    for name in args.preset or ["cpu-small", "paper"]:
        model = Multipath(PRESETS[name]).to(dev)
        params = sum(p.numel() for p in model.parameters())
        opt = torch.optim.Adam(model.parameters(), lr=1e-4)

        def step():
            opt.zero_grad()
            loss = gmm_nll(*model(b), b["future_xy"], b["future_valid"])
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), 0.4)
            opt.step()

        for _ in range(max(args.warmup, 1)):
            step()
        sync()
        times = []
        for _ in range(args.steps):
            t = time.perf_counter()
            step()
            sync()
            times.append((time.perf_counter() - t) * 1e3)
        ms, best = sum(times) / len(times), min(times)
        with torch.no_grad():
            model(b)
            sync()
            reps = max(args.steps, 3)
            t = time.perf_counter()
            for _ in range(reps):
                model(b)
            sync()
            per_s = reps * args.batch / (time.perf_counter() - t)
        print(f"{name:<10} {params:>10} params   train step {ms:>9.1f} ms (best {best:.1f})   inference {per_s:>8.1f} samples/s")


if __name__ == "__main__":
    main()
