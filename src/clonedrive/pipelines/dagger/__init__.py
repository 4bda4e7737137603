"""DAgger (Ross, Gordon & Bagnell 2011): the network drives, the expert labels what it sees.

Behaviour cloning only sees the states the expert visits; a network that drifts off the
expert's line meets states it never saw and does not know how to leave them. DAgger lets the
network drive and has the expert label every frame the network's own driving reaches, then
trains on all the labels gathered so far. ``run_dagger(config, base_run, out_dir)`` starts from
a trained run folder (``clonedrive train --out BASE``: its model, config and recipe) and, per
iteration ``k = 1..iterations``:

1. **collects**: on each of ``config.tracks`` one car drives ``laps`` lap(s) at up to
   ``speed_mph``. Each step the expert's controls are applied with probability
   ``beta_k = beta * beta_decay ** (k - 1)``, the network's otherwise (Ross et al.'s mixture
   policy). A **safety takeover** hands the car to the expert when it is about to leave the road
   (its side, now or ``takeover_preview_s`` ahead on its heading, within ``takeover_margin_m`` of
   an edge) until it is back near the centreline, heading along the road; takeovers are
   counted (per km, below), not hidden. The expert
   (:class:`~clonedrive.episode.drivers.ExpertDriver` as the runner's **labeller**) labels
   every visited frame with its steering and its target speed; every frame is written as a
   recording, ``iter_k/data/<track>/`` (``driving_log.csv`` + ``IMG/`` + ``target_speed.csv``:
   the steering column holds the expert's label, throttle, brake and speed what the car did);
2. **aggregates** the base recipe and every iteration's recordings so far (center camera and
   its mirror image: the labels are the expert's for exactly that view);
3. **retrains** the network from the previous iteration's weights (``epochs`` epochs,
   ``iter_k/train/``);
4. **evaluates** it in closed loop: on the benchmark's ``bench_splits`` of ``bench_suite``
   (``clonedrive bench``, ``iter_k/bench/bench.json``), or with no bench splits on
   ``eval_tracks`` and ``eval_unseen`` generated tracks (evaluate's unseen tracks, never used
   for collection; ``iter_k/eval/eval.json``, splits ``builtin`` and ``unseen``).

**Human takeovers** (HG-DAgger, Kelly et al. 2019): ``human`` lists recordings made in
``clonedrive web``'s takeover mode, where a model drove and a person took the car whenever it
went wrong; such a recording holds only the person's rows, the labels. They are aggregated with
the expert's from iteration 1 on (center camera and its mirror image, like them).

Iteration 0 is the base model's evaluation. With ``plain`` the comparison DAgger needs is run
too: **plain cloning with as many extra expert labels** -- the expert itself drives the same
tracks (with ``plain_noise`` steering noise, its labels clean) until it has recorded as many
rows as DAgger collected in all, and the base model is retrained on base + those rows for as
many epochs as DAgger trained in all (``plain/``). So any difference comes from *where* the
labels are, not how many. With ``plain_each`` it is also run at every earlier iteration's
label count and epochs (``plain_NN/``), so the two methods are compared as curves, not only
where both may have reached the benchmark's ceiling.

``dagger.json`` holds per iteration: beta, labels collected (and in total), expert share of the
driving, takeovers and takeovers per km, and the evaluation's success %, interventions per km,
lap-time ratio and smoothness ratio per split, plus the plain-cloning row; ``dagger.png`` plots
them. Each stage's folder is reused when complete, so an interrupted run continues.

The parts: ``config`` (the settings and file names), ``mixed_driver`` (who drives each step),
``stages`` (collect, record the plain-cloning labels, aggregate, retrain), ``measure``
(closed-loop figures), ``loop`` (the whole run) and ``figures`` (the plot and the table).
"""
