"""PPO with parameter sharing across robots, in the spirit of CleanRL's ``ppo_continuous_action.py``.

Read top to bottom: the hyperparameters (one dataclass, the paper's values where it gives them, deviations
explained in the field docstrings and the model card), the rollout over many arenas, GAE, the clipped update, the
logged diagnostics (approx-KL, clip fraction, explained variance). Every robot of every arena is one sample of the
same shared policy; transitions of robots that are done are masked out.

Observation normalisation: the running statistics are frozen while a rollout is collected and the update runs
(so PPO's ratios start at exactly 1), then the rollout's observations are folded in.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import torch
from torch import nn

from rpf_fly.learn.env import EnvConfig, EpisodeStats, SwarmEnv
from rpf_fly.learn.model import ActorCritic, ModelConfig

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class PPOConfig:
    """Training hyperparameters. Paper Table I: lr 3e-4 decayed by 0.999, gamma 0.999, tau 0.9, clip 0.2,
    c1 0.5, c2 0.001, batch 100, 1 epoch, 1000 episodes of at most 1000 steps."""

    seed: int = 0
    kind: Literal["rpf", "rpf-mean", "ppo"] = "rpf"
    """rpf: attention + gains; rpf-mean: mean embedding + gains (RPF-2); ppo: attention + heading change."""
    arena: Literal["a", "b", "both"] = "both"
    curriculum: tuple[str, ...] = ()
    """Scene families of rpf_fly.sim.generators (training seed stream) drawn instead of ``arena``; empty: the
    paper's arenas."""
    episodes: int = 4000
    """Stop after this many finished arena episodes (each arena episode is one of the paper's episodes)."""
    max_updates: int = 10_000
    n_arenas: int = 48
    """Parallel arenas, 6 robots each: 288 robots share each step."""
    rollout_steps: int = 128
    """Steps per arena between updates (the paper updates every Z = 100 steps)."""
    lr: float = 3e-4
    lr_decay: float = 0.995
    """Multiplied into the learning rate after every update (the paper decays 0.999 per episode; with ~20 arena
    episodes per update, 0.995 per update decays at a comparable pace without freezing learning)."""
    min_lr: float = 3e-5
    gamma: float = 0.999
    gae_lambda: float = 0.9
    """The paper's tau."""
    clip: float = 0.2
    vf_coef: float = 0.5
    ent_coef: float = 0.001
    epochs: int = 4
    """The paper uses 1 epoch of batch 100; 4 epochs over 4096-sample minibatches uses each rollout better on a CPU."""
    minibatch_size: int = 4096
    max_grad_norm: float = 0.5
    reward_scale: float = 0.01
    """Rewards (hundreds per event) are scaled into the critic's comfortable range."""
    max_neighbours: int = 10
    obstacle_radius: float = 0.5
    """Arena A obstacles; the vanilla-PPO baseline trains with 0.1 m (the paper could not train it at 0.5 m)."""
    progress_reward: Literal["potential", "paper"] = "potential"
    collision_penalty: float = 500.0
    """The paper's -100 lets the policy trade collisions for shorter paths (docs/learning.md); 500 does not."""
    guidance: Literal["none", "path"] = "none"
    """``path``: train with the planner's global guidance (RPF-3); ``none``: the paper's environment."""
    margin: float = 0.0
    """Clearance beyond contact (m) the planner keeps and the reward asks for; RPF-3 trains with the product's 0.05."""
    margin_penalty: float = 20.0
    capture_radius: float = 0.0
    """The planner's capture rule in the training environment; 0 (the paper's) turns it off."""
    threads: int = 2
    checkpoint_every: int = 10
    eval_every: int = 10
    """Every this many updates, run the deterministic policy on fixed validation scenes (never the paper
    missions, never the evaluation seeds of the model card) and keep the best weights."""
    eval_episodes: int = 32
    eval_seed: int = 424242

    def model_config(self) -> ModelConfig:
        return ModelConfig(
            embedding="mean" if self.kind == "rpf-mean" else "attention",
            action="heading" if self.kind == "ppo" else "gains",
            max_neighbours=self.max_neighbours,
        )

    def env_config(self) -> EnvConfig:
        return EnvConfig(
            n_arenas=self.n_arenas,
            arena=self.arena,
            curriculum=tuple(self.curriculum),
            action="heading" if self.kind == "ppo" else "gains",
            gamma=self.gamma,
            max_neighbours=self.max_neighbours,
            obstacle_radius=self.obstacle_radius,
            progress_reward=self.progress_reward,
            collision_penalty=self.collision_penalty,
            guidance=self.guidance,
            margin=self.margin,
            margin_penalty=self.margin_penalty,
            capture_radius=self.capture_radius,
        )


@dataclass
class UpdateLog:
    """One row of the training curve (CSV)."""

    update: int
    episodes: int
    env_steps: int
    wall_s: float
    steps_per_s: float
    lr: float
    mean_return: float
    success_rate: float
    success_rate_a: float
    success_rate_b: float
    collision_rate: float
    policy_loss: float
    value_loss: float
    entropy: float
    approx_kl: float
    clip_fraction: float
    explained_variance: float
    eta_mean: float
    lam_mean: float
    eval_return: float = float("nan")
    eval_success: float = float("nan")
    eval_collisions: float = float("nan")


def _tensors(obs) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Flatten an env observation (arenas, robots, ...) into batch tensors."""
    local = torch.from_numpy(obs.local.reshape(-1, obs.local.shape[-1]))
    neighbours = torch.from_numpy(obs.neighbours.reshape(-1, *obs.neighbours.shape[-2:]))
    mask = torch.from_numpy(obs.mask.reshape(-1, obs.mask.shape[-1]).astype(np.float32))
    return local, neighbours, mask


class Trainer:
    """Owns the environment, the model, the optimiser and the training state; :meth:`run` trains."""

    def __init__(self, config: PPOConfig, out_dir: Path):
        self.config = config
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        torch.manual_seed(config.seed)
        torch.set_num_threads(config.threads)
        self.env = SwarmEnv(config.env_config(), seed=config.seed)
        self.model = ActorCritic(config.model_config())
        self.optimizer = torch.optim.Adam(self.model.parameters(), lr=config.lr, eps=1e-5)
        self.update = 0
        self.episodes: list[EpisodeStats] = []
        self.env_steps = 0
        self.wall_s = 0.0
        self.history: list[UpdateLog] = []
        self.best: dict | None = None
        self.skipped_minibatches = 0
        self.best_score: tuple[float, float] = (-1.0, -float("inf"))
        self._warm_up_normalisers()

    # --------------------------------------------------------------------------------------- state

    @property
    def checkpoint_path(self) -> Path:
        return self.out_dir / "checkpoint.pt"

    def save_checkpoint(self) -> None:
        """Everything needed to continue: weights, optimiser, counters, curves (the env restarts fresh scenes)."""
        torch.save(
            {
                "config": dataclasses.asdict(self.config),
                "model": self.model.state_dict(),
                "optimizer": self.optimizer.state_dict(),
                "update": self.update,
                "episodes": [dataclasses.asdict(e) for e in self.episodes],
                "env_steps": self.env_steps,
                "wall_s": self.wall_s,
                "history": [dataclasses.asdict(h) for h in self.history],
                "torch_rng": torch.get_rng_state(),
                "best": self.best,
                "best_score": self.best_score,
            },
            self.checkpoint_path,
        )

    def load_checkpoint(self) -> None:
        state = torch.load(self.checkpoint_path, weights_only=False)
        self.model.load_state_dict(state["model"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.update = state["update"]
        self.episodes = [EpisodeStats(**e) for e in state["episodes"]]
        self.env_steps = state["env_steps"]
        self.wall_s = state["wall_s"]
        self.history = [UpdateLog(**h) for h in state["history"]]
        torch.set_rng_state(state["torch_rng"])
        self.best = state.get("best")
        self.best_score = tuple(state.get("best_score", (-1.0, -float("inf"))))
        # Fresh scenes after a resume: reseed the environment from the update counter, deterministically.
        self.env = SwarmEnv(self.config.env_config(), seed=self.config.seed + 7919 * self.update)

    def _warm_up_normalisers(self) -> None:
        obs = self.env.observation
        local, neighbours, mask = _tensors(obs)
        self.model.update_normalisers(local, neighbours, mask)

    # ------------------------------------------------------------------------------------- training

    def run(self, progress: Callable[[UpdateLog], None] | None = None) -> list[UpdateLog]:
        """Train until ``episodes`` arena episodes finished (or ``max_updates``); checkpoints and curves as it goes."""
        c = self.config
        while len(self.episodes) < c.episodes and self.update < c.max_updates:
            started = time.perf_counter()
            batch = self._collect()
            losses = self._learn(batch)
            self.update += 1
            self.wall_s += time.perf_counter() - started
            for group in self.optimizer.param_groups:
                group["lr"] = max(c.lr * c.lr_decay**self.update, c.min_lr)
            log = self._log(batch, losses, time.perf_counter() - started)
            if self.update % c.eval_every == 0:
                self._validate(log)
            self.history.append(log)
            self._write_curve()
            if progress:
                progress(log)
            if self.update % c.checkpoint_every == 0:
                self.save_checkpoint()
        self.save_checkpoint()
        return self.history

    def _collect(self) -> dict:
        """Run every arena for ``rollout_steps`` with the current policy; returns the rollout with GAE advantages."""
        c = self.config
        env, model = self.env, self.model
        n_robots = env.config.n_robots
        t_max, robots = c.rollout_steps, c.n_arenas * n_robots
        a_size = model.config.action_size
        local = torch.zeros(t_max, robots, 4)
        neighbours = torch.zeros(t_max, robots, c.max_neighbours, 3)
        mask = torch.zeros(t_max, robots, c.max_neighbours)
        u = torch.zeros(t_max, robots, a_size)
        logp = torch.zeros(t_max, robots)
        value = torch.zeros(t_max, robots)
        reward = torch.zeros(t_max, robots)
        done = torch.zeros(t_max, robots)
        valid = torch.zeros(t_max, robots)
        actions = []
        finished: list[EpisodeStats] = []
        for t in range(t_max):
            local[t], neighbours[t], mask[t] = _tensors(env.observation)
            with torch.no_grad():
                u[t], logp[t], value[t] = model.act(local[t], neighbours[t], mask[t])
                action = model.to_action(u[t])
            result = env.step(action.numpy().reshape(c.n_arenas, n_robots, a_size))
            reward[t] = torch.from_numpy(result.reward.reshape(-1)).float() * c.reward_scale
            done[t] = torch.from_numpy(result.done.reshape(-1)).float()
            valid[t] = torch.from_numpy(result.valid.reshape(-1)).float()
            actions.append(action[valid[t] > 0])
            finished += result.episodes
        self.env_steps += t_max * c.n_arenas
        self.episodes += finished
        with torch.no_grad():
            next_value = model.value(*_tensors(env.observation))
        # GAE, backward. A done transition does not bootstrap; transitions of robots already done are zero and
        # marked done, so nothing flows across an episode boundary.
        advantages = torch.zeros(t_max, robots)
        last = torch.zeros(robots)
        for t in reversed(range(t_max)):
            not_done = 1.0 - torch.maximum(done[t], 1.0 - valid[t])
            following = next_value if t == t_max - 1 else value[t + 1]
            delta = reward[t] + c.gamma * following * not_done - value[t]
            last = (delta + c.gamma * c.gae_lambda * not_done * last) * valid[t]
            advantages[t] = last
        returns = advantages + value
        keep = valid.reshape(-1) > 0
        flat = lambda x: x.reshape(t_max * robots, *x.shape[2:])[keep]  # noqa: E731
        return {
            "local": flat(local),
            "neighbours": flat(neighbours),
            "mask": flat(mask),
            "u": flat(u),
            "logp": flat(logp),
            "value": flat(value),
            "advantages": flat(advantages),
            "returns": flat(returns),
            "actions": torch.cat(actions) if actions else torch.zeros(0, a_size),
            "finished": finished,
        }

    def _learn(self, batch: dict) -> dict[str, float]:
        """Clipped PPO epochs over the valid transitions, then fold the rollout into the observation statistics."""
        c = self.config
        model = self.model
        n = batch["local"].shape[0]
        kls, clips, pls, vls, ents = [], [], [], [], []
        for _ in range(c.epochs):
            order = torch.randperm(n)
            for start in range(0, n, c.minibatch_size):
                idx = order[start : start + c.minibatch_size]
                if idx.numel() < 2:  # a 1-sample remainder has no advantage std (NaN): skip it
                    continue
                logp, entropy, value = model.evaluate(
                    batch["local"][idx], batch["neighbours"][idx], batch["mask"][idx], batch["u"][idx]
                )
                log_ratio = logp - batch["logp"][idx]
                ratio = log_ratio.exp()
                with torch.no_grad():
                    kls.append(float(((ratio - 1) - log_ratio).mean()))
                    clips.append(float(((ratio - 1.0).abs() > c.clip).float().mean()))
                adv = batch["advantages"][idx]
                adv = (adv - adv.mean()) / (adv.std() + 1e-8)
                policy_loss = torch.max(-adv * ratio, -adv * ratio.clamp(1 - c.clip, 1 + c.clip)).mean()
                old_value = batch["value"][idx]
                clipped = old_value + (value - old_value).clamp(-c.clip, c.clip)
                value_loss = (
                    0.5 * torch.max((value - batch["returns"][idx]) ** 2, (clipped - batch["returns"][idx]) ** 2).mean()
                )
                loss = policy_loss - c.ent_coef * entropy.mean() + c.vf_coef * value_loss
                if not torch.isfinite(loss):  # never let one bad minibatch poison the weights
                    self.skipped_minibatches += 1
                    logger.warning("update %d: non-finite loss, minibatch skipped", self.update)
                    continue
                self.optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(model.parameters(), c.max_grad_norm)
                self.optimizer.step()
                pls.append(float(policy_loss.detach()))
                vls.append(float(value_loss.detach()))
                ents.append(float(entropy.mean().detach()))
        model.update_normalisers(batch["local"], batch["neighbours"], batch["mask"])
        values, returns = batch["value"], batch["returns"]
        var = float(returns.var()) if n > 1 else 0.0
        explained = float(1 - (returns - values).var() / var) if var > 0 else float("nan")
        return {
            "policy_loss": float(np.mean(pls)) if pls else 0.0,
            "value_loss": float(np.mean(vls)) if vls else 0.0,
            "entropy": float(np.mean(ents)) if ents else 0.0,
            "approx_kl": float(np.mean(kls)) if kls else 0.0,
            "clip_fraction": float(np.mean(clips)) if clips else 0.0,
            "explained_variance": explained,
        }

    def _validate(self, log: UpdateLog) -> None:
        """Deterministic policy on the fixed validation scenes; remember the best weights (success, then return)."""
        from rpf_fly.learn.evaluate import evaluate_policy

        result = evaluate_policy(self.model, self.config.env_config(), self.config.eval_seed, self.config.eval_episodes)
        log.eval_return, log.eval_success, log.eval_collisions = (
            result.mean_return,
            result.success_rate,
            float(result.collisions),
        )
        score = (result.success_rate, result.mean_return)
        if score > self.best_score:
            self.best_score = score
            self.best = {
                "update": self.update,
                "model": {k: v.clone() for k, v in self.model.state_dict().items()},
                "success": result.success_rate,
                "return": result.mean_return,
            }

    def best_model(self) -> ActorCritic:
        """The weights with the best validation score (the current ones if no validation ran)."""
        if self.best is None:
            return self.model
        model = ActorCritic(self.config.model_config())
        model.load_state_dict(self.best["model"])
        return model

    # ----------------------------------------------------------------------------------------- logs

    def _log(self, batch: dict, losses: dict[str, float], seconds: float) -> UpdateLog:
        recent = self.episodes[-200:]

        def rate(kind: str | None) -> float:
            sel = [e for e in recent if kind is None or e.arena_kind == kind]
            return float(np.mean([e.success for e in sel])) if sel else float("nan")

        actions = batch["actions"]
        gains = actions.shape[-1] == 2 and actions.shape[0] > 0
        return UpdateLog(
            update=self.update,
            episodes=len(self.episodes),
            env_steps=self.env_steps,
            wall_s=round(self.wall_s, 2),
            steps_per_s=self.config.rollout_steps
            * self.config.n_arenas
            * self.env.config.n_robots
            / max(seconds, 1e-9),
            lr=self.optimizer.param_groups[0]["lr"],
            mean_return=float(np.mean([e.mean_return for e in recent])) if recent else float("nan"),
            success_rate=rate(None),
            success_rate_a=rate("a"),
            success_rate_b=rate("b"),
            collision_rate=float(np.mean([e.collided > 0 for e in recent])) if recent else float("nan"),
            eta_mean=float(actions[:, 0].mean()) if gains else float("nan"),
            lam_mean=float(actions[:, 1].mean()) if gains else float("nan"),
            **losses,
        )

    def _write_curve(self) -> None:
        path = self.out_dir / "training_curve.csv"
        with path.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=[fld.name for fld in dataclasses.fields(UpdateLog)])
            writer.writeheader()
            for row in self.history:
                writer.writerow(dataclasses.asdict(row))

    def summary(self) -> dict:
        return {
            "config": dataclasses.asdict(self.config),
            "updates": self.update,
            "episodes": len(self.episodes),
            "env_steps": self.env_steps,
            "wall_s": self.wall_s,
        }


def write_summary(trainer: Trainer) -> Path:
    path = trainer.out_dir / "summary.json"
    path.write_text(json.dumps(trainer.summary(), indent=2))
    return path
