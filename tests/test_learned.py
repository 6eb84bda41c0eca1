"""Learned driving policies: features, the model, checkpoints, training configs, and training.

Fast tests use one observation of a hand-built scene and a random-initialised small model;
the end-to-end training tests (a tiny dataset recorded once per module, two trainings) run
with the slow tests.
"""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from flax import nnx

from lantern_jax.apps.training.config import ConfigError, load_config
from lantern_jax.core.constants import NUM_WAYPOINTS
from lantern_jax.policies.learned.checkpoint import (
    CheckpointError,
    checkpoint_policy,
    learned_params,
    load_model,
    make_act,
    model_policy,
    new_model,
    read_meta,
    save_model,
    shipped_path,
)
from lantern_jax.policies.learned.features import (
    NAV_TEXTS,
    WORD_DIM,
    features,
    nav_token_table,
    navigation_instruction,
)
from lantern_jax.policies.learned.model import ModelConfig
from lantern_jax.scenarios.handmade import straight_scene
from lantern_jax.scenarios.warnings import text_tables, warning_language
from lantern_jax.sim.observe import observe
from lantern_jax.sim.state import init_state
from lantern_jax.types.language import MAX_TOKENS, NUMBER_ID, PAD_ID
from lantern_jax.types.world import present

SMALL = ModelConfig(width=16, heads=2)


@pytest.fixture(scope="module")
def tables(embedding):
    return embedding, jnp.asarray(nav_token_table())


def warned(obs, text_id: int, pos=(30.0, 0.0)):
    """The observation with the warning ``text_id`` delivered at ``pos`` (ego frame, m)."""
    tokens, values = warning_language(
        jnp.int32(text_id), jnp.bool_(True), jnp.asarray(pos, jnp.float32)
    )
    return obs.replace(warning_tokens=tokens, warning_values=values)


def test_features_shapes_and_ranges(obs, tables):
    f = features(obs, "front", *tables)
    assert f.ego.shape == (9,) and f.route.shape == (52,)
    assert f.objects.shape == (obs.actor_xy.shape[0], SMALL.object_features)
    assert f.ranges.shape == obs.range_image.shape
    assert float(f.ranges.min()) >= 0.0 and float(f.ranges.max()) <= 1.0
    assert f.text.shape == (tables[0].shape[1],)
    assert float(f.warning) == 0.0 and float(f.has_position) == 0.0
    assert np.all(np.asarray(f.position) == 0.0)
    for leaf in jax.tree.leaves(f):
        assert np.all(np.isfinite(np.asarray(leaf, np.float32)))
    with pytest.raises(ValueError, match="rig"):
        features(obs, "fisheye", *tables)


def test_navigation_instruction_follows_the_route_bend():
    """Ego frame: x forward, y right; a route bending to negative y is a left turn."""
    straight = jnp.stack([jnp.arange(24.0), jnp.zeros(24)], -1)
    left = straight.at[-1].set(jnp.array([22.5, -2.0]))
    right = straight.at[-1].set(jnp.array([22.5, 2.0]))
    got = [int(navigation_instruction(r)) for r in (straight, left, right)]
    assert [NAV_TEXTS[i] for i in got] == list(NAV_TEXTS)


def test_warning_replaces_the_navigation_text(obs, tables):
    """While a warning is active the text channel is the warning's, otherwise the
    navigation instruction's; the stated position only enters when the text states one."""
    f0 = features(obs, "front", *tables)
    f1 = features(warned(obs, 0), "front", *tables)
    assert float(f1.warning) == 1.0
    assert not np.allclose(np.asarray(f0.text), np.asarray(f1.text))
    assert float(f1.has_position) == float(text_tables().has_position[0])
    np.testing.assert_allclose(np.asarray(f1.position), np.array([30.0, 0.0]) / 50.0, atol=1e-6)


def test_model_output_is_ordered_finite_waypoints(obs, tables):
    model = new_model(SMALL, seed=0)
    wp = model(features(obs, "front", *tables))
    assert wp.shape == (NUM_WAYPOINTS, 2) and wp.dtype == jnp.float32
    assert np.all(np.isfinite(np.asarray(wp)))


def test_language_model_reads_the_text_and_languageless_one_does_not(obs, tables):
    """A different warning text changes a language model's plan (FiLM), never the plan of a
    model without language."""
    lang = new_model(SMALL, seed=1)
    mute = new_model(ModelConfig(width=16, heads=2, language=False), seed=1)
    a, b = warned(obs, 0), warned(obs, 3)
    fa, fb = features(a, "front", *tables), features(b, "front", *tables)
    assert float(jnp.max(jnp.abs(lang(fa) - lang(fb)))) > 1e-4
    assert float(jnp.max(jnp.abs(mute(fa) - mute(fb)))) == 0.0


def test_text_gradient_is_finite_and_nonzero(obs, tables):
    """d(plan)/d(text embedding) of a language model: the text pathway is trainable."""
    model = new_model(SMALL, seed=2)
    f = features(warned(obs, 0), "front", *tables)
    g = jax.grad(lambda t: jnp.sum(model(f.replace(text=t))))(f.text)
    assert np.all(np.isfinite(np.asarray(g))) and float(jnp.max(jnp.abs(g))) > 0.0


READER = ModelConfig(width=16, heads=2, text_encoder="attention")
BIGRAM = ModelConfig(width=16, heads=2, text_encoder="bigram")
#: Every text encoder that reads the words in order.
ORDERED = pytest.mark.parametrize("config", [READER, BIGRAM], ids=["attention", "bigram"])


def reordered(obs, text_id: int):
    """The warning ``text_id`` with its other tokens in reverse order; the numbers keep their
    places (so the stated position is the same) and the padding stays at the end."""
    o = warned(obs, text_id)
    tok = np.asarray(o.warning_tokens).copy()
    slots = np.flatnonzero((tok != PAD_ID) & (tok != NUMBER_ID))
    tok[slots] = tok[slots][::-1]
    return o.replace(warning_tokens=jnp.asarray(tok))


def test_features_give_the_text_s_words_in_order(obs, tables):
    """``words`` are the leading columns of the table's rows of the delivered tokens in order,
    zero at padding; the mask is the text's tokens."""
    o = warned(obs, 2)
    f = features(o, "front", *tables)
    tok = np.asarray(o.warning_tokens)
    assert f.words.shape == (MAX_TOKENS, WORD_DIM) and f.words.dtype == jnp.float32
    np.testing.assert_array_equal(np.asarray(f.word_mask), tok != PAD_ID)
    want = np.asarray(tables[0])[tok, :WORD_DIM] * (tok != PAD_ID)[:, None]
    np.testing.assert_array_equal(np.asarray(f.words), want)


@ORDERED
def test_only_the_ordered_encoders_read_word_order(obs, tables, config):
    """The pooled text is a bag of words: reversing the words leaves a pooled model's plan as
    it was (to float rounding), and changes the plan of a model that reads them in order."""
    a, b = warned(obs, 0), reordered(obs, 0)
    fa, fb = features(a, "front", *tables), features(b, "front", *tables)
    pooled, reader = new_model(SMALL, seed=1), new_model(config, seed=1)
    np.testing.assert_allclose(np.asarray(pooled(fa)), np.asarray(pooled(fb)), atol=1e-5)
    assert float(jnp.max(jnp.abs(reader(fa) - reader(fb)))) > 1e-4


@ORDERED
def test_ordered_encoders_ignore_padding(obs, tables, config):
    """Whatever the padded rows hold, the reading of the text is the same (masked attention,
    masked pairs and pooling)."""
    f = features(warned(obs, 1), "front", *tables)
    model = new_model(config, seed=2)
    noise = jax.random.normal(jax.random.PRNGKey(0), f.words.shape)
    g = f.replace(words=jnp.where(f.word_mask[:, None], f.words, noise))
    np.testing.assert_allclose(np.asarray(model(f)), np.asarray(model(g)), atol=1e-5)


@ORDERED
def test_word_gradient_is_finite_and_nonzero(obs, tables, config):
    """d(plan)/d(word embeddings) of an ordered encoder: nonzero on the text's tokens, zero
    on padding."""
    model = new_model(config, seed=3)
    f = features(warned(obs, 0), "front", *tables)
    g = jax.grad(lambda w: jnp.sum(model(f.replace(words=w))))(f.words)
    g = np.asarray(g)
    mask = np.asarray(f.word_mask)
    assert np.all(np.isfinite(g))
    assert np.all(np.abs(g[mask]).max(axis=1) > 0.0) and np.all(g[~mask] == 0.0)


@ORDERED
def test_ordered_model_saves_loads_and_refuses_the_pooled_architecture(obs, tables, tmp_path,
                                                                       config):  # fmt: skip
    model = new_model(config, seed=4)
    save_model(model, tmp_path / "r")
    back = load_model(tmp_path / "r", expect=config)
    f = features(warned(obs, 1), "front", *tables)
    np.testing.assert_array_equal(np.asarray(model(f)), np.asarray(back(f)))
    with pytest.raises(CheckpointError, match=r"config\.text_encoder"):
        load_model(tmp_path / "r", expect=SMALL)


def test_bigram_reading_matches_a_numpy_reference(obs, tables):
    """The bigram encoder's summary, written out in NumPy: the mean over the text's adjacent
    token pairs of (first word's projection) * (second word's other projection)."""
    model = new_model(BIGRAM, seed=5)
    f = features(warned(obs, 2), "front", *tables)
    words, mask = np.asarray(f.words, np.float64), np.asarray(f.word_mask)
    w1, b1 = (np.asarray(v[...], np.float64) for v in (model.embed_words.kernel,
                                                       model.embed_words.bias))  # fmt: skip
    w2, b2 = (np.asarray(v[...], np.float64) for v in (model.embed_next.kernel,
                                                       model.embed_next.bias))  # fmt: skip
    n = int(mask.sum())
    want = np.mean([(words[i] @ w1 + b1) * (words[i + 1] @ w2 + b2) for i in range(n - 1)], 0)
    got = np.asarray(model._read_words(f.words, f.word_mask))
    assert n > 5 and got.shape == (BIGRAM.width,)
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-6)


def test_bigram_encoder_tells_a_swapped_pair_apart(obs, tables):
    """Two adjacent words swapped: the bag of words is the same, the ordered pairs are not
    (the pair's two words go through different projections)."""
    f = features(warned(obs, 0), "front", *tables)
    model = new_model(BIGRAM, seed=6)
    swapped = f.words.at[0].set(f.words[1]).at[1].set(f.words[0])
    g = f.replace(words=swapped)
    before, after = model._read_words(f.words, f.word_mask), model._read_words(g.words, g.word_mask)
    assert float(jnp.max(jnp.abs(before - after))) > 1e-4


def test_bigram_word_tables_read_what_the_slots_read(obs, tables):
    """Training's reading through the projected vocabulary (``word_tables``, with
    ``text_vocabulary`` of the batch) gives a bigram model the plans and the loss gradient of
    the per-slot reading, to float32 rounding, on a batch of texts spread over the bank and
    the navigation instructions; the other encoders have no tables."""
    from lantern_jax.apps.training.fit import make_loss, text_vocabulary

    bank = np.asarray(text_tables().tokens)
    tokens = bank[np.linspace(0, len(bank) - 1, 12).astype(int)]
    tokens[::3] = PAD_ID  # no text delivered: these read the navigation instruction
    n = len(tokens)
    batch = jax.tree.map(lambda x: jnp.stack([x] * n), obs)
    batch = batch.replace(warning_tokens=jnp.asarray(tokens))
    emb, nav = tables
    vocab = text_vocabulary(tokens, np.asarray(nav))
    assert np.all(np.diff(vocab) > 0) and set(np.unique(tokens)) <= set(vocab.tolist())
    model = new_model(BIGRAM, seed=7)
    graphdef, params = nnx.split(model)

    @jax.jit  # the tables arguments, as training passes them (not a 33 MB captured constant)
    def plans(p, voc, emb, nav):
        m = nnx.merge(graphdef, p)
        word_tables = m.word_tables(emb, voc)
        f = jax.vmap(lambda o: features(o, "front", emb, nav))(batch)
        return jax.vmap(m)(f), jax.vmap(lambda g: m(g, word_tables))(f), f.warning

    slots, read, warning = plans(params, jnp.asarray(vocab), emb, nav)
    assert not np.all(np.asarray(warning))  # some examples read the navigation text
    np.testing.assert_allclose(np.asarray(read), np.asarray(slots), rtol=1e-5, atol=1e-5)
    targets = jnp.zeros((n, NUM_WAYPOINTS, 2))
    columns = {k: v for k, v in vars(batch).items() if v is not None}  # training's example columns
    loss = jax.jit(jax.value_and_grad(make_loss(graphdef, "front")))
    (v0, g0), (v1, g1) = loss(params, columns, targets, emb, nav), loss(
        params, columns, targets, emb, nav, jnp.asarray(vocab))
    np.testing.assert_allclose(float(v1), float(v0), rtol=1e-6)
    for a, b in zip(jax.tree.leaves(g0), jax.tree.leaves(g1), strict=True):
        np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-4, atol=1e-6)
    assert float(jnp.max(jnp.abs(g1["embed_words"]["kernel"][...]))) > 0.0
    for config in (SMALL, READER):
        assert new_model(config, seed=7).word_tables(emb, jnp.asarray(vocab)) is None


def test_a_description_written_before_the_text_encoder_loads_as_pooled(saved):
    """Checkpoints written before ``text_encoder`` and ``text_layers`` existed describe the
    pooled architecture of that time."""
    from lantern_jax.policies.learned.checkpoint import description_hash

    meta = json.loads(saved.with_suffix(".json").read_text())
    del meta["config"]["text_encoder"], meta["config"]["text_layers"]
    del meta["config"]["object_pool"]  # a later field still: the mean of that time
    meta["sha256"] = description_hash(meta)
    saved.with_suffix(".json").write_text(json.dumps(meta))
    assert load_model(saved, expect=SMALL).config == SMALL


@pytest.mark.parametrize("field, value", [("text_encoder", "lstm"), ("object_pool", "max")])
def test_an_unknown_text_encoder_or_object_pool_is_refused(saved, field, value):
    from lantern_jax.policies.learned.checkpoint import description_hash

    meta = json.loads(saved.with_suffix(".json").read_text())
    meta["config"][field] = value
    meta["sha256"] = description_hash(meta)
    saved.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(CheckpointError, match=rf"config\.{field}: '{value}' not one of"):
        load_model(saved)


def test_masked_max_takes_each_features_largest_seen_value():
    """Hand-built tokens: each column's maximum over the seen rows, a hidden row's larger
    values ignored, zeros when nothing is seen; the gradient reaches only the maximum's row."""
    from lantern_jax.policies.learned.model import _masked_max

    tokens = jnp.asarray([[1.0, -4.0, 0.5], [3.0, -2.0, 0.25], [9.0, 9.0, 9.0]])  # (3, 3)
    mask = jnp.asarray([True, True, False])
    np.testing.assert_array_equal(np.asarray(_masked_max(tokens, mask)), [3.0, -2.0, 0.5])
    np.testing.assert_array_equal(np.asarray(_masked_max(tokens, jnp.zeros(3, bool))), 0.0)
    grad = np.asarray(jax.grad(lambda t: jnp.sum(_masked_max(t, mask)))(tokens))
    np.testing.assert_array_equal(grad, [[0, 0, 1], [1, 1, 0], [0, 0, 0]])
    assert np.all(np.isfinite(np.asarray(jax.grad(
        lambda t: jnp.sum(_masked_max(t, jnp.zeros(3, bool))))(tokens))))  # fmt: skip


def test_mean_max_pooling_reads_one_actor_and_ignores_unseen_slots(obs, tables, tmp_path):
    """``object_pool = "mean_max"``: a training config's setting reaches the architecture and
    its checkpoint (a mean-pooled expectation refuses it); the plan does not depend on what an
    unseen actor slot holds (the padding invariance of the mean pool kept), the trunk's input
    is wider by the max, and gradients reach the new weights (finite, non-zero)."""
    from lantern_jax.apps.training.config import TrainConfig
    from lantern_jax.apps.training.fit import model_config

    trained = TrainConfig(name="x", recipe="base", width=16, heads=2, object_pool="mean_max")
    maxed = model_config(trained, ranges=SMALL.ranges)
    assert maxed == ModelConfig(width=16, heads=2, object_pool="mean_max")
    model = new_model(maxed, seed=5)
    save_model(model, tmp_path / "maxed")
    assert load_model(tmp_path / "maxed", expect=maxed).config == maxed
    with pytest.raises(CheckpointError, match="object_pool"):
        load_model(tmp_path / "maxed", expect=SMALL)
    assert model.trunk.layers[0].kernel.shape[0] == 4 * 16
    assert new_model(SMALL, seed=5).trunk.layers[0].kernel.shape[0] == 3 * 16
    f = features(obs, "front", *tables)
    slots, width = f.objects.shape  # three actors seen, drawn at random; the rest unseen
    seen = jax.random.normal(jax.random.PRNGKey(1), (slots, width))
    f = f.replace(objects=seen, mask=jnp.arange(slots) < 3)
    hidden = jnp.where(f.mask[:, None], f.objects, 1e3)  # junk in every unseen slot
    np.testing.assert_allclose(np.asarray(model(f.replace(objects=hidden))),
                               np.asarray(model(f)), rtol=1e-6, atol=1e-6)  # fmt: skip
    graphdef, params = nnx.split(model, nnx.Param)

    def loss(p):
        return jnp.sum(nnx.merge(graphdef, p)(f) ** 2)

    g = nnx.State(jax.grad(loss)(params))
    kernel = np.asarray(g["trunk"]["layers"][0]["kernel"][...])
    assert np.all(np.isfinite(kernel)) and np.abs(kernel[16:32]).max() > 0.0  # the max's rows


def test_policy_act_is_pure_and_batchable(obs, tables):
    model = new_model(SMALL, seed=3)
    pol = model_policy("m", model, embedding=tables[0])
    params = pol.init(jax.random.PRNGKey(0))
    one = jax.jit(pol.act)(params, obs)
    batch = jax.tree.map(lambda x: jnp.stack([x, x]), obs)
    two = jax.jit(jax.vmap(pol.act, (None, 0)))(params, batch)
    np.testing.assert_allclose(np.asarray(two[0]), np.asarray(one), atol=1e-5)
    assert pol.reads_warning and pol.sensors == ("front_camera", "warning")


def test_overfits_a_tiny_set(obs, tables):
    """Sixteen observations with distinct targets: a few hundred AdamW steps bring the L1 loss
    to a small fraction of its start (the model and the text pathway can fit)."""
    rng = np.random.default_rng(0)
    n = 16
    batch = jax.tree.map(lambda x: jnp.stack([x] * n), obs)
    tokens = text_tables().tokens
    ids = np.arange(n) % 6
    speed = rng.uniform(0.0, 10.0, n).astype(np.float32)
    batch = batch.replace(
        warning_tokens=jnp.asarray(tokens[ids]),
        ego_speed=jnp.asarray(speed),
    )  # fmt: skip
    # the plan's length follows the speed, its bend follows the warning text
    k = np.arange(1, NUM_WAYPOINTS + 1) * 0.25
    targets = np.stack([np.stack([k * v, 0.05 * k * v * (i % 3 - 1)], -1)
                        for i, v in zip(ids, speed, strict=True)]).astype(np.float32)  # fmt: skip
    model = new_model(SMALL, seed=4)
    graphdef, params = nnx.split(model)
    tx = optax.adam(3e-3)
    opt = tx.init(params)

    def loss(p, tabs):
        m = nnx.merge(graphdef, p)
        pred = jax.vmap(lambda o: m(features(o, "front", *tabs)))(batch)
        return jnp.mean(jnp.abs(pred - targets))

    @jax.jit  # the tables an argument, as training passes them (not a 33 MB captured constant)
    def step(p, s, tabs):
        v, g = jax.value_and_grad(loss)(p, tabs)
        u, s = tx.update(g, s, p)
        return optax.apply_updates(p, u), s, v

    losses = []  # each step's loss is that of the parameters before its update
    for _ in range(401):
        params, opt, value = step(params, opt, tables)
        losses.append(value)
    first, last = float(losses[0]), float(losses[-1])  # before any update and after 400
    assert last < 0.15 * first, (first, last)


def test_save_load_gives_identical_actions(obs, tables, tmp_path):
    model = new_model(SMALL, seed=5)
    save_model(model, tmp_path / "m", dict(note="x"))
    back = load_model(tmp_path / "m", expect=SMALL)
    f = features(warned(obs, 1), "front", *tables)
    np.testing.assert_array_equal(np.asarray(model(f)), np.asarray(back(f)))
    meta = json.loads((tmp_path / "m.json").read_text())
    assert meta["note"] == "x" and meta["config"]["width"] == 16


def test_checkpoint_policy_is_named_and_acts(obs, tmp_path):
    save_model(new_model(SMALL, seed=6), tmp_path / "mine",
               dict(train_config=dict(name="mine", recipe="coop")))  # fmt: skip
    pol = checkpoint_policy(tmp_path / "mine.msgpack")
    assert pol.name == "mine"
    wp = jax.jit(pol.act)(pol.init(jax.random.PRNGKey(0)), obs)
    assert np.all(np.isfinite(np.asarray(wp)))
    assert checkpoint_policy(tmp_path / "mine", name="other").name == "other"


# -- a catalogue of bad checkpoints -------------------------------------------------------------


@pytest.fixture
def saved(tmp_path):
    save_model(new_model(SMALL, seed=7), tmp_path / "m")
    return tmp_path / "m"


def test_missing_checkpoint_is_named(tmp_path):
    with pytest.raises(CheckpointError, match="no such checkpoint"):
        checkpoint_policy(tmp_path / "absent.msgpack")


def test_unreadable_description_is_named(saved):
    saved.with_suffix(".json").write_text("{not json")
    with pytest.raises(CheckpointError, match=r"m\.json"):
        load_model(saved)


def test_tampered_weights_are_refused(saved):
    w = saved.with_suffix(".msgpack")
    data = bytearray(w.read_bytes())
    data[-1] ^= 0xFF
    w.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="params_sha256"):
        load_model(saved)


def test_other_architecture_is_refused_naming_the_field(saved):
    with pytest.raises(CheckpointError, match=r"config\.width"):
        load_model(saved, expect=ModelConfig(width=32, heads=2))


def test_unknown_config_field_is_refused(saved):
    meta = json.loads(saved.with_suffix(".json").read_text())
    meta["config"]["depth"] = 3
    saved.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(CheckpointError, match=r"config\.depth"):
        load_model(saved)


def test_weights_of_another_shape_are_refused(saved, tmp_path):
    """A description edited to another width (its own hash recomputed, the weights' hash still
    matching the weights)."""
    from lantern_jax.policies.learned.checkpoint import description_hash

    meta = json.loads(saved.with_suffix(".json").read_text())
    meta["config"]["width"] = 32
    meta["sha256"] = description_hash(meta)
    saved.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(CheckpointError, match="shape|does not fit"):
        load_model(saved)


# -- training configs ---------------------------------------------------------------------------


def write(tmp_path, text: str):
    p = tmp_path / "t.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    "text, match",
    [
        ("[train]\nrecipe = 'base'\n", r"train\.name: missing"),
        ("[train]\nname = 'x'\nrecipe = 'fancy'\n", r"train\.recipe"),
        ("[train]\nname = 'x'\nrecipe = 'coop'\n", r"train\.init_from"),
        ("[train]\nname = 'x'\nrecipe = 'base'\nepochs = 'six'\n", r"train\.epochs must be int"),
        ("[train]\nname = 'x'\nrecipe = 'base'\nepochs = 0\n", r"train\.epochs"),
        ("[train]\nname = 'x'\nrecipe = 'base'\nlr = -1.0\n", r"train\.lr"),
        ("[train]\nname = 'x'\nrecipe = 'base'\nbase_mix = 1.5\n", r"train\.base_mix"),
        ("[train]\nname = 'x'\nrecipe = 'base'\nwidth = 10\nheads = 4\n", r"train\.heads"),
        ("[train]\nname = 'x'\nrecipe = 'base'\nlearning_rate = 1.0\n", r"learning_rate"),
        ("[train]\nname = 'x'\nrecipe = 'base'\nepochs = true\n", r"train\.epochs"),
        (
            "[train]\nname = 'x'\nrecipe = 'base'\nexclude_crossing = 'all'\n",
            r"train\.exclude_crossing: 'all' not one of both, onset, none",
        ),
        (
            "[train]\nname = 'x'\nrecipe = 'base'\nexclude_crossing = 1\n",
            r"train\.exclude_crossing must be str",
        ),
        (
            "[train]\nname = 'x'\nrecipe = 'base'\ndistractor_texts = 'lanes'\n",
            r"train\.distractor_texts: 'lanes' not one of position, position_and_lane",
        ),
        (
            "[train]\nname = 'x'\nrecipe = 'base'\ntext_encoder = 'lstm'\n",
            r"train\.text_encoder: 'lstm' not one of pooled, attention, bigram",
        ),
        (
            "[train]\nname = 'x'\nrecipe = 'surround'\ntext_encoder = 'attention'\n",
            r"train\.text_encoder: the surround recipe reads no text",
        ),
        ("[train]\nname = 'x'\nrecipe = 'base'\ntext_layers = 0\n", r"train\.text_layers"),
        (
            "[train]\nname = 'x'\nrecipe = 'base'\nobject_pool = 'max'\n",
            r"train\.object_pool: 'max' not one of mean, mean_max",
        ),
        (
            "[train]\nname = 'x'\nrecipe = 'base'\ncounterfactual_stated_share = 1.5\n",
            r"train\.counterfactual_stated_share: must be in \[0, 1\], got 1\.5",
        ),
        (
            "[train]\nname = 'x'\nrecipe = 'base'\ncounterfactual_stated_share = 0.5\n",
            r"train\.counterfactual_stated_share: .*only with counterfactual_positions = "
            r"\"stated\"",
        ),
        ("[evaluate]\nname = 'x'\n", r"\[train\]"),
        ("[train\nname = 'x'\n", "not valid TOML"),
    ],
)
def test_bad_training_configs_are_named(tmp_path, text, match):
    with pytest.raises(ConfigError, match=match):
        load_config(write(tmp_path, text))


def test_shipped_training_configs_load():
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent / "configs"
    paths = sorted(p for p in root.glob("train_*.toml") if p.stem != "train_ppo")  # [ppo]
    assert {p.stem for p in paths} >= {"train_base", "train_coop", "train_surround"}
    for p in paths:
        cfg = load_config(p)
        assert cfg.name.startswith("learned-")


def test_every_shipped_model_is_registered_and_loads():
    """Each shipped checkpoint is a registered policy under the name it was trained under, with
    its description, and its act gives finite waypoints; every load is the same program (the
    architecture is static in its parameters, so every evaluation naming it, or another model
    of the same architecture, reuses one compiled program)."""
    from lantern_jax.policies.registry import SHIPPED_MODELS, get_policy, policy_names
    from lantern_jax.sim.engine import Program

    world = straight_scene([], length=120.0, speed=8.0)
    state = jax.jit(init_state)(world)
    see = jax.jit(observe, static_argnums=2)  # one program per sensor declaration
    assert set(SHIPPED_MODELS) <= set(policy_names())
    for name, desc in SHIPPED_MODELS.items():
        pol = get_policy(name)
        assert Program(get_policy(name)) == Program(pol)
        assert pol.name == name and pol.description == desc
        assert read_meta(shipped_path(name))["train_config"]["name"] == name
        obs = see(world, state, pol.sensors)
        plan = jax.jit(pol.act)(pol.init(jax.random.PRNGKey(0)), obs)
        assert plan.shape == (NUM_WAYPOINTS, 2) and bool(jnp.all(jnp.isfinite(plan)))


def test_make_act_matches_model_call(obs, tables):
    model = new_model(SMALL, seed=8)
    graphdef, _ = nnx.split(model)
    params = learned_params(model, tables[0])
    a = make_act(SMALL, graphdef)(params, obs)
    b = model(features(obs, "front", *tables))
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.slow  # compiles its own programs; run by the slow tier
def test_surround_rig_reads_the_simulators_360_degree_view(tmp_path):
    """A surround-rig model's act asks for the six-camera rig: the simulator fills
    ``Observation.surround`` for it (and only for it), its features read that view, and it
    drives a closed-loop rollout to finite waypoints."""
    from lantern_jax.core.constants import SURROUND_FOV
    from lantern_jax.sim.rollout import rollout
    from lantern_jax.sim.sense import SURROUND_RAYS, camera_view

    world = straight_scene([], length=120.0, speed=8.0, s_warn=22.0,
                           s_event=31.0, s_conflict=40.0, hazard_index=0, clear_s=22.0)  # fmt: skip
    state = init_state(world)
    assert observe(world, state).surround is None
    around = jax.jit(lambda w, s: observe(w, s, ("surround_rig",)))(world, state).surround
    rig = camera_view(world, state.ego, state.actors, SURROUND_FOV, SURROUND_RAYS)
    on = present(world.actors, state.actors)
    np.testing.assert_array_equal(np.asarray(around.visible), np.asarray(rig.visible & on))
    np.testing.assert_array_equal(np.asarray(around.ranges), np.asarray(rig.ranges))
    assert around.ranges.shape == (SURROUND_RAYS,)

    cfg = ModelConfig(width=16, heads=2, rig="surround", language=False, ranges=SURROUND_RAYS)
    pol = model_policy("learned-surround-test", new_model(cfg, seed=1))
    assert pol.surround and pol.sensors == ("front_camera", "surround_rig")
    with pytest.raises(ValueError, match="surround"):
        features(observe(world, state), "surround", *(pol.init(None).embedding,
                 pol.init(None).nav_tokens))  # fmt: skip
    final, _ = jax.jit(lambda w: rollout(w, pol, pol.init(None), 40))(world)
    assert np.isfinite(np.asarray(final.ego.xy)).all() and float(final.t) > 0


def test_an_epochs_batches_form_groups_of_steps_the_last_one_padded():
    """Batches in order, :data:`~lantern_jax.apps.training.fit.STEPS_PER_CALL` to a group; the
    last group repeats the epoch's last batch in rows marked not valid; batches of different
    sizes are refused (one program serves every group)."""
    from lantern_jax.apps.training.fit import step_groups

    batches = [np.arange(3 * k, 3 * k + 3) for k in range(7)]
    groups = step_groups(batches, 3)
    assert [g.idx.shape for g in groups] == [(3, 3)] * 3
    np.testing.assert_array_equal(np.concatenate([g.idx for g in groups])[:7], np.stack(batches))
    assert [g.valid.tolist() for g in groups] == [[True] * 3, [True] * 3, [True, False, False]]
    np.testing.assert_array_equal(groups[-1].idx[1:], np.stack([batches[-1]] * 2))
    assert [g.steps for g in groups] == [3, 3, 1] and sum(g.examples for g in groups) == 21
    assert step_groups([], 3) == []
    with pytest.raises(ValueError, match="sizes"):
        step_groups([np.arange(3), np.arange(2)], 3)
