"""Trains the tracking policy with PPO, evaluates it and exports `<name>.onnx`, `<name>.json`, `<name>.golden.json`.

    PY="$(bash policies/train/setup_venv.sh)"
    "$PY" policies/train/train.py --name tracker --steps 6000000 --seed 1      # the default model
    "$PY" policies/train/train.py --smoke                                      # a few thousand steps, temp dir

The output directory defaults to policies/models (`--smoke` defaults to a fresh temporary directory).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import asdict, astuple, dataclass, replace
from pathlib import Path

import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback

import artifacts
import policy as pol
from env import RewardWeights
from evaluate import PD_GAINS, baselines, evaluate
from vecenv import EPISODE_STEPS, TrackingVecEnv

MODELS = Path(__file__).resolve().parent.parent / "models"


@dataclass
class Config:
    """PPO hyper-parameters (γ and the clip range are the paper's)."""

    n_envs: int = 32
    n_steps: int = 512
    batch_size: int = 4096
    n_epochs: int = 10
    learning_rate: float = 3e-4
    final_learning_rate: float = 3e-5
    gamma: float = 0.95
    gae_lambda: float = 0.9
    clip_range: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    log_std_init: float = -1.2
    average_decay: float = 0.95  # per PPO update, see ActorAverage
    odd_actor: bool = True  # see policy.make_actor_odd
    episode_steps: int = EPISODE_STEPS
    obs_scale: tuple = pol.OBS_SCALE
    reward_weights: tuple = astuple(RewardWeights())  # λs1, λs2, λo of eq. (16)


SMOKE = Config(n_envs=8, n_steps=128, batch_size=512, n_epochs=2)


def override(cfg: Config, assignments: list[str]) -> Config:
    """Applies KEY=VALUE overrides (a tuple field takes comma-separated numbers)."""
    changes = {}
    for item in assignments:
        key, value = item.split("=", 1)
        default = getattr(cfg, key)
        if isinstance(default, tuple):
            changes[key] = tuple(float(x) for x in value.split(","))
        elif isinstance(default, bool):
            changes[key] = value.lower() in ("1", "true", "yes")
        else:
            changes[key] = type(default)(value)
    return replace(cfg, **changes)


class ActorAverage(BaseCallback):
    """Exponential moving average of the actor's weights (mean network), updated after every PPO update: it
    smooths out the update-to-update jitter of the deterministic action that limits tracking precision."""

    def __init__(self, decay: float):
        super().__init__()
        self.decay = decay

    def _init_callback(self) -> None:
        policy = self.model.policy
        self.params = [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters()]
        self.average = [p.detach().clone() for p in self.params]

    def _on_rollout_start(self) -> None:
        with torch.no_grad():
            for a, p in zip(self.average, self.params):
                a.mul_(self.decay).add_(p, alpha=1.0 - self.decay)

    def _on_step(self) -> bool:
        return True

    def load(self, values: list[torch.Tensor]) -> None:
        """Copies `values` into the actor's weights (e.g. `self.average`: the exported policy is the averaged one)."""
        with torch.no_grad():
            for v, p in zip(values, self.params):
                p.copy_(v)

    @contextmanager
    def applied(self):
        """Temporarily loads the averaged weights into the policy."""
        saved = [p.detach().clone() for p in self.params]
        self.load(self.average)
        try:
            yield
        finally:
            self.load(saved)


class Progress(BaseCallback):
    """Prints the evaluation RMSE of the deterministic policy (raw and averaged) every `every` steps."""

    def __init__(self, every: int, start: float, average: ActorAverage):
        super().__init__()
        self.every, self.start, self.next, self.average = every, start, every, average

    def _rmse(self) -> str:
        res = evaluate(lambda obs, _ff: pol.deterministic_action(self.model.policy, obs))
        return " ".join(f"{v['total']:.4f}" for v in res.values())

    def _on_step(self) -> bool:
        if self.num_timesteps >= self.next:
            self.next += self.every
            raw = self._rmse()
            with self.average.applied():
                averaged = self._rmse()
            std = float(self.model.policy.log_std.detach().exp().mean())
            print(
                f"[{time.time() - self.start:6.0f}s] {self.num_timesteps:>9} steps  RMSE ellipse/figure8/rectangle "
                f"raw {raw}  averaged {averaged}  std={std:.3f}",
                flush=True,
            )
        return True


def train(cfg: Config, steps: int, seed: int, threads: int, log_every: int) -> tuple[PPO, float]:
    """Runs PPO; returns the model and the training wall time (s)."""
    torch.set_num_threads(threads)
    venv = TrackingVecEnv(cfg.n_envs, seed, cfg.episode_steps, RewardWeights(*cfg.reward_weights))
    lr0, lr1 = cfg.learning_rate, cfg.final_learning_rate
    model = PPO(
        "MlpPolicy",
        venv,
        learning_rate=lambda remaining: lr1 + (lr0 - lr1) * remaining,
        n_steps=cfg.n_steps,
        batch_size=cfg.batch_size,
        n_epochs=cfg.n_epochs,
        gamma=cfg.gamma,
        gae_lambda=cfg.gae_lambda,
        clip_range=cfg.clip_range,
        ent_coef=cfg.ent_coef,
        vf_coef=cfg.vf_coef,
        max_grad_norm=cfg.max_grad_norm,
        policy_kwargs=pol.policy_kwargs(cfg.obs_scale, cfg.log_std_init),
        seed=seed,
        device="cpu",
        verbose=0,
    )
    if cfg.odd_actor:
        pol.make_actor_odd(model.policy)
    start = time.time()
    average = ActorAverage(cfg.average_decay)
    callbacks = [average, Progress(log_every, start, average)] if log_every else [average]
    model.learn(total_timesteps=steps, callback=callbacks)
    average.load(average.average)
    return model, time.time() - start


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, help="output directory (default policies/models; temp dir with --smoke)")
    ap.add_argument("--name", default="tracker")
    ap.add_argument("--steps", type=int, default=6_000_000, help="environment steps")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    ap.add_argument("--log-every", type=int, default=500_000, help="steps between progress lines (0: none)")
    ap.add_argument("--smoke", action="store_true", help="a few thousand steps, to check the pipeline end to end")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a Config field")
    args = ap.parse_args(argv)
    cfg = override(SMOKE if args.smoke else Config(), args.set)
    steps = min(args.steps, 4096) if args.smoke else args.steps
    out = args.out or (Path(tempfile.mkdtemp(prefix="airroads-smoke-")) if args.smoke else MODELS)
    out.mkdir(parents=True, exist_ok=True)

    model, wall = train(cfg, steps, args.seed, args.threads, 0 if args.smoke else args.log_every)
    onnx_path = out / f"{args.name}.onnx"
    pol.export(model.policy, onnx_path)
    artifacts.write_golden(onnx_path.with_suffix(".golden.json"), onnx_path, args.seed)
    result = evaluate(pol.OnnxPolicy(onnx_path))
    manifest = artifacts.write_manifest(
        onnx_path.with_suffix(".json"),
        onnx_path,
        seed=args.seed,
        training_steps=int(model.num_timesteps),
        wall_time_s=round(wall, 1),
        torch_threads=args.threads,
        smoke=args.smoke,
        reward={"equation": "paper eq. (16), see env.py", **RewardWeights(*cfg.reward_weights).as_dict()},
        ppo={**asdict(cfg), "policy_net": [128, 128], "value_net": [128, 128], "activation": "tanh"},
        evaluation={
            "definition": "50 s (1000 steps) from the reference start, UAV at rest there; RMSE of p(k) - p_r(k), "
            "k = 1..1000, total and per axis (m); see evaluate.py",
            "policy": result,
            "baselines": {"gains": {k: list(v) for k, v in PD_GAINS.items()}, **baselines()},
        },
    )
    print(f"wrote {onnx_path} (+ .json, .golden.json) in {out}; training {wall:.0f} s")
    for name, r in result.items():
        print(f"  {name:9s} RMSE {r['total']:.4f} m (x {r['x']:.4f}, y {r['y']:.4f}, max {r['max']:.4f})")
    return manifest


if __name__ == "__main__":
    main(sys.argv[1:])
