"""The recommendation: the best candidate, the fastest near it, and the lines printed."""

from __future__ import annotations


def recommend(rows: list[dict], tolerance_db: float = 1.0) -> dict:
    """The best candidate, the fastest within `tolerance_db` of it, and the fastest
    average-method candidate within the tolerance (for those who keep the paper's method)."""
    best = max(rows, key=lambda r: r["psnr"])
    near = [r for r in rows if r["psnr"] >= best["psnr"] - tolerance_db]
    fastest = min(near, key=lambda r: r["seconds"])
    avg = [r for r in near if r["method"] == "average"]
    return {
        "tolerance_db": tolerance_db,
        "best": best["label"],
        "best_psnr": best["psnr"],
        "fastest_near_best": fastest["label"],
        "fastest_near_best_psnr": fastest["psnr"],
        "fastest_near_best_seconds": fastest["seconds"],
        "fastest_average_near_best": min(avg, key=lambda r: r["seconds"])["label"] if avg else None,
    }


def summary_lines(res: dict) -> list[str]:
    setup, rec = res["setup"], res["recommendation"]
    cands = [r for r in res["rows"] if r["role"] == "candidate"]
    by = {r["label"]: r for r in cands}
    fast, best = by[rec["fastest_near_best"]], by[rec["best"]]
    lines = [
        f"blurset tradeoff: {setup['uid']} view {setup['view']} level {setup['level']}: "
        f"{setup['motion_px']:.1f} px of motion at {setup['resolution']} px; "
        f"{len(cands)} candidates in {setup['total_seconds']:.0f} s",
        f"  best: {best['label']} ({best['latents']} x {best['samples_per_frame']} samples): "
        f"{best['psnr']:.1f} dB in {best['seconds']:.2f} s",
        f"  fastest within {rec['tolerance_db']:g} dB of it: {fast['label']}: "
        f"{fast['psnr']:.1f} dB in {fast['seconds']:.2f} s",
    ]
    if rec["fastest_average_near_best"] and rec["fastest_average_near_best"] != fast["label"]:
        a = by[rec["fastest_average_near_best"]]
        lines.append(
            f"  keeping latent averaging: {a['label']} ({a['latents']} x "
            f"{a['samples_per_frame']}): {a['psnr']:.1f} dB in {a['seconds']:.2f} s"
        )
    lines.append(f"  recommendation: {_flags(fast)}")
    return lines


def _flags(r: dict) -> str:
    budget = f"--samples-total {r['budget']} --blur-budget flat"
    if r["method"] == "motion_blur":
        return f"--blur-method motion_blur {budget}"
    if r["sampling"] == "auto-stratified":
        return f"--latents auto --latent-positions stratified {budget}"
    return f"--latents {r['latents']} --latent-positions {r['sampling']} {budget}"
