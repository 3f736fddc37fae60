"""Evaluate a saved run: success rate with its 95 % interval, and a video of a few episodes.

    python -m training.evaluate RUN_DIR [--episodes 100] [--seed S] [--video-episodes 3] [--no-video]
                                        [--gif PATH [--gif-success]] [--best]

RUN_DIR is a folder written by training.runner.train_agent (config.json + model.zip): the output
folder of training.train.
--best evaluates best_model.zip (the better of the best evaluation during training and the final model, on the
same fresh episodes when training ended: training.best_choice) and, on the same episodes, the final model beside
it, both with their intervals, into RUN_DIR/evaluation_best.json. Episodes are deterministic-policy
episodes on fresh seeds (default: the run's evaluation seeds). The interval is Wilson's score
interval for a binomial proportion. Videos (gymnasium RecordVideo, needs MoviePy: the `video` extra)
go to RUN_DIR/videos/; without MoviePy the evaluation runs and prints its numbers, and one line says
how to get the videos; results to RUN_DIR/evaluation.json. --gif writes one episode as an animated
GIF (Pillow, which matplotlib brings; every other frame; no pygame needed), e.g. for the docs: the first evaluation episode,
or with --gif-success the first one that succeeded (the first one if none did).
"""
from __future__ import annotations

import argparse
import importlib.util
import json
from pathlib import Path

import numpy as np

from training.best_choice import wilson_interval  # noqa: F401 (its home was here)

VIDEO_HINT = ('no video: recording needs MoviePy, the "video" extra (pip install -e ".[video]" in the clone); '
              '--no-video skips it')


def record_video(env_id: str, model, folder: Path, episodes: int, seed: int) -> list[str]:
    """MP4s of `episodes` deterministic episodes from seeds seed, seed + 1, ... (RecordVideo)."""
    import gymnasium as gym
    from gymnasium.wrappers import RecordVideo
    import penny_env  # noqa: F401
    env = RecordVideo(gym.make(env_id, render_mode="rgb_array"), str(folder), episode_trigger=lambda e: True,
                      name_prefix="episode", disable_logger=True)
    for e in range(episodes):
        obs, _ = env.reset(seed=seed + e)
        done = False
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, _, term, trunc, _ = env.step(action)
            done = term or trunc
    env.close()
    return sorted(str(p) for p in folder.glob("*.mp4"))


def write_gif(env_id: str, model, path: Path, seed: int) -> int:
    """An animated GIF of one deterministic episode from `seed` (every other frame); returns its frame count."""
    import gymnasium as gym
    from PIL import Image
    import penny_env  # noqa: F401
    env = gym.make(env_id, render_mode="rgb_array")
    fps = env.metadata.get("render_fps", 20)
    obs, _ = env.reset(seed=seed)
    frames, done = [env.render()], False
    while not done:
        action, _ = model.predict(obs, deterministic=True)
        obs, _, term, trunc, _ = env.step(action)
        done = term or trunc
        frames.append(env.render())
    env.close()
    images = [Image.fromarray(f) for f in frames[::2]]
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(2000 / fps), loop=0)
    return len(images)


def evaluate_run(run_dir, episodes: int = 100, seed: int | None = None, video_episodes: int = 3,
                 gif: str | None = None, gif_success: bool = False, best: bool = False) -> dict:
    from training.episodes import run_episodes
    from training.runner import eval_seed, load_run
    run_dir = Path(run_dir)
    if not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes must be a positive integer, got {episodes!r}")
    model_file = "best_model.zip" if best else "model.zip"
    cfg, model = load_run(run_dir, model_file)
    seed = eval_seed(cfg["seed"]) if seed is None else seed
    r = run_episodes(cfg["env_id"], lambda o: model.predict(o, deterministic=True)[0], episodes, seed)
    k = int(np.sum(r["success"]))
    lo, hi = wilson_interval(k, episodes)
    res = {"env_id": cfg["env_id"], "algo": cfg["algo"], "model": str(run_dir / model_file), "episodes": episodes, "seed": seed,
           "successes": k,
           "success_rate": k / episodes, "ci95_wilson": [lo, hi], "mean_return": float(np.mean(r["return"])),
           "mean_impacts": float(np.mean(r["impacts"]))}
    if video_episodes > 0 and importlib.util.find_spec("moviepy") is None:
        res["video_skipped"] = VIDEO_HINT  # the numbers above stand without it
    elif video_episodes > 0:
        res["videos"] = record_video(cfg["env_id"], model, run_dir / "videos", video_episodes, seed)
    if gif:
        first = next((j for j, ok in enumerate(r["success"]) if ok), 0) if gif_success else 0
        write_gif(cfg["env_id"], model, Path(gif), seed + first)
        res["gif"], res["gif_seed"], res["gif_success"] = str(gif), seed + first, bool(r["success"][first])
    if best:  # the final model on the same episodes, beside it: one score alone does not say which is better
        res["final"] = _final_beside(run_dir, cfg, episodes, seed)
    (run_dir / ("evaluation_best.json" if best else "evaluation.json")).write_text(json.dumps(res, indent=2))
    return res


def _final_beside(run_dir: Path, cfg: dict, episodes: int, seed: int) -> dict:
    """model.zip's scores on the episodes --best played, and best.json's record of how best_model.zip was chosen."""
    from training.best_choice import describe, scores
    from training.episodes import run_episodes
    from training.runner import load_run
    _, final = load_run(run_dir, "model.zip")
    out = scores(run_episodes(cfg["env_id"], lambda o: final.predict(o, deterministic=True)[0], episodes, seed))
    out["model"] = str(run_dir / "model.zip")
    record = run_dir / "best.json"
    if record.is_file():
        try:
            out["choice"] = describe(json.loads(record.read_text()))
        except (ValueError, KeyError, TypeError):
            out["choice"] = ""
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run_dir")
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--video-episodes", type=int, default=3)
    ap.add_argument("--no-video", action="store_true")
    ap.add_argument("--gif", default=None, help="also write an episode as an animated GIF here (the first one)")
    ap.add_argument("--gif-success", action="store_true", help="the GIF shows the first episode that succeeded")
    ap.add_argument("--best", action="store_true",
                    help="evaluate best_model.zip, and the final model beside it on the same episodes")
    args = ap.parse_args(argv)
    try:
        res = evaluate_run(args.run_dir, args.episodes, args.seed, 0 if args.no_video else args.video_episodes,
                           args.gif, args.gif_success, args.best)
    except ValueError as exc:
        ap.error(str(exc))
    lo, hi = res["ci95_wilson"]
    which = "best_model.zip" if args.best else "model.zip"
    print(f"{res['algo'].upper()} on {res['env_id']} ({which}): success {res['success_rate']:.3f} "
          f"(95 % Wilson interval [{lo:.3f}, {hi:.3f}]) over {res['episodes']} episodes from seed {res['seed']}; "
          f"mean return {res['mean_return']:.2f}")
    if "final" in res:
        f = res["final"]
        print(f"the final model (model.zip) on the same episodes: success {f['success_rate']:.3f} (95 % Wilson interval "
              f"[{f['ci95_wilson'][0]:.3f}, {f['ci95_wilson'][1]:.3f}]); mean return {f['mean_return']:.2f}")
        if f.get("choice"):
            print(f["choice"])
    for v in res.get("videos", []):
        print("video:", v)
    if "video_skipped" in res:
        print(res["video_skipped"])
    if "gif" in res:
        print(f"gif: {res['gif']} (episode seed {res['gif_seed']}, {'a success' if res['gif_success'] else 'not a success'})")
    return res


if __name__ == "__main__":
    main()
