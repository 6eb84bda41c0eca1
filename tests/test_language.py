"""Warning texts as language: tokenisation, the token table, the pretrained embedding and the
files it is loaded from (the installed ``wordllama`` package, read offline)."""

from __future__ import annotations

import importlib.util

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.scenarios import warnings
from lantern_jax.scenarios.warnings import DEFAULT_BANK, TEMPLATES, TOKEN
from lantern_jax.types import language


@pytest.fixture(scope="module")
def tok():
    return language.load_tokenizer()


@pytest.fixture(scope="module")
def table():
    return language.load_embedding()


# ---------------------------------------------------------------------------------------------
# tokenisation
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("text_id", range(len(TEMPLATES)))
def test_canonical_templates_round_trip(text_id):
    ids = language.tokenize(TEMPLATES[text_id])
    assert ids.count(language.NUMBER_ID) == 2  # the position's x and y
    assert language.detokenize(ids) == TEMPLATES[text_id]
    assert language.detokenize(language.pad(ids)) == TEMPLATES[text_id]  # padding is dropped


def test_every_bank_text_round_trips_through_its_table_row():
    rows = warnings.token_table(DEFAULT_BANK)
    assert rows.shape == (len(DEFAULT_BANK), language.MAX_TOKENS) and rows.dtype == np.int32
    for e in DEFAULT_BANK:
        assert language.detokenize(rows[e.text_id]) == e.text, e.text_id
    assert (rows[warnings.EMPTY_TEXT_ID] == language.PAD_ID).all()  # the empty text: no tokens


def test_tokens_equal_the_tokenizers_output(tok):
    """Each piece between placeholders is exactly the tokenizer's encoding of that piece and a
    position is the ids of ``( <number> , <number> )``; a text without a placeholder is exactly
    the tokenizer's encoding of the whole text."""
    position = [
        *tok.encode("(", add_special_tokens=False).ids,
        language.NUMBER_ID,
        *tok.encode(",", add_special_tokens=False).ids,
        language.NUMBER_ID,
        *tok.encode(")", add_special_tokens=False).ids,
    ]
    for e in DEFAULT_BANK:
        want: list[int] = []
        for i, piece in enumerate(e.text.split(TOKEN)):
            if i:
                want += position
            if piece.strip():
                want += tok.encode(piece.strip(), add_special_tokens=False).ids
        got = warnings.token_table()[e.text_id]
        n = len(want)
        assert got[:n].tolist() == want, e.text_id
        assert (got[n:] == language.PAD_ID).all()
        if TOKEN not in e.text:
            assert want == tok.encode(e.text, add_special_tokens=False).ids


def test_pieces_keep_the_full_texts_tokens(tok):
    """Tokenising around the position changes only the position's own tokens: the words before
    and after it get the ids they have in the full delivered sentence."""
    text = TEMPLATES[0]
    full = tok.encode(text.replace(TOKEN, "(14.2, 3.1)"), add_special_tokens=False).ids
    ids = language.tokenize(text)
    k = ids.index(language.NUMBER_ID) - 1  # the opening parenthesis
    tail = len(ids) - (k + len(language.position_tokens()))
    assert full[:k] == ids[:k] and full[-tail:] == ids[-tail:]


def test_number_and_padding_ids_never_come_from_text(tok):
    """The byte-fallback tokenizer never emits <unk> (the number token) or </s> (padding)."""
    for text in [e.text.replace(TOKEN, "(14.2, -3.1)") for e in DEFAULT_BANK] + ["ünïcödé ✓ 🚗"]:
        ids = tok.encode(text, add_special_tokens=False).ids
        assert language.NUMBER_ID not in ids and language.PAD_ID not in ids


def test_the_value_channel_writes_the_position_as_the_text_does():
    """The delivered string read back from tokens and values is exactly ``render_warning``."""
    lookup = jax.jit(lambda i, p: warnings.warning_language(i, jnp.asarray(True), p))
    for e in DEFAULT_BANK:
        for pos in ((14.24, -3.15), (0.04, -0.04), (100.0, 0.5)):
            tokens, values = lookup(jnp.int32(e.text_id), jnp.asarray(pos, jnp.float32))
            got = warnings.warning_string(tokens, values)
            assert got == warnings.render_warning(e.text_id, pos), (e.text_id, pos, got)
            numbers = np.asarray(values)[np.asarray(tokens) == language.NUMBER_ID]
            assert len(numbers) == (2 if e.has_position else 0)
            assert (
                np.count_nonzero(np.asarray(values)[np.asarray(tokens) != language.NUMBER_ID]) == 0
            )


@pytest.mark.parametrize(
    "text",
    [
        "The car at <FRONT_CAR_POS> .",  # punctuation after a space: it would come back glued
        "The car at<FRONT_CAR_POS> is stopped.",
        "The car at  <FRONT_CAR_POS> is stopped.",  # two spaces
        " The car is stopped.",  # leading space
        "   ",
    ],
)
def test_texts_that_would_not_round_trip_are_refused(text):
    with pytest.raises(ValueError, match="text"):
        language.tokenize(text)


@pytest.mark.parametrize(
    "text",
    [
        "The car at <FRONT_CAR_POS>.",
        "Watch the rider near <FRONT_CAR_POS>; the rider will enter your path.",
        "At <FRONT_CAR_POS>, a car waits.",
    ],
)
def test_punctuation_glued_to_a_position_round_trips(text):
    ids = language.tokenize(text)
    assert language.detokenize(ids) == text
    position = "(12.3, -0.5)"
    values = np.zeros(len(ids), np.float32)
    slots = language.number_slots(ids)
    values[slots] = (12.3, -0.5)
    assert language.detokenize(ids, values) == text.replace(language.PLACEHOLDER, position)


def test_too_long_text_is_refused():
    with pytest.raises(ValueError, match="exceed the fixed length 48"):
        language.pad(list(range(3, 3 + language.MAX_TOKENS + 1)))


def test_token_table_is_built_once(monkeypatch):
    calls = []
    real = language.tokenize

    def counting(text, *a, **k):
        calls.append(text)
        return real(text, *a, **k)

    monkeypatch.setattr(language, "tokenize", counting)
    warnings._text_tables.cache_clear()
    first = warnings.text_tables(DEFAULT_BANK)
    assert len(calls) == len(DEFAULT_BANK)
    assert warnings.text_tables(DEFAULT_BANK) is first
    lookup = jax.jit(
        lambda i: warnings.warning_language(i, jnp.asarray(True), jnp.ones(2), DEFAULT_BANK)
    )
    for i in (0, 7, len(DEFAULT_BANK) - 1):
        tokens, values = lookup(jnp.int32(i))
        np.testing.assert_array_equal(np.asarray(tokens), first.tokens[i])
        assert bool(np.any(np.asarray(values) != 0)) == DEFAULT_BANK[i].has_position
    assert len(calls) == len(DEFAULT_BANK)  # lookups (traced or not) never tokenise again


def test_lookup_of_inactive_or_unknown_text_is_padding():
    for tid, active in ((0, False), (-1, True), (len(DEFAULT_BANK), True)):
        tokens, values = warnings.warning_language(
            jnp.int32(tid), jnp.asarray(active), jnp.ones(2), DEFAULT_BANK
        )
        assert (np.asarray(tokens) == language.PAD_ID).all()
        assert not np.asarray(values).any()


# ---------------------------------------------------------------------------------------------
# the files and the error when they are missing
# ---------------------------------------------------------------------------------------------
def test_assets_come_from_the_installed_package():
    spec = importlib.util.find_spec("wordllama")
    assert spec is not None
    root = language.asset_root()
    assert (root / language.TOKENIZER_FILE).is_file()
    assert (root / language.WEIGHTS_FILE).is_file()


def test_missing_tokenizer_file_is_named(tmp_path):
    with pytest.raises(language.LanguageAssetError, match="l2_supercat_tokenizer_config.json"):
        language.load_tokenizer(str(tmp_path))


def test_missing_weights_file_is_named(tmp_path):
    with pytest.raises(language.LanguageAssetError, match="l2_supercat_256.safetensors"):
        language.load_embedding(str(tmp_path))


def test_corrupted_weights_file_is_named(tmp_path):
    bad = tmp_path / language.WEIGHTS_FILE
    bad.parent.mkdir(parents=True)
    bad.write_bytes(b"not a safetensors file")
    msg = "l2_supercat_256.safetensors cannot be read"
    with pytest.raises(language.LanguageAssetError, match=msg):
        language.load_embedding(str(tmp_path))


def test_missing_package_says_what_to_install(monkeypatch):
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    with pytest.raises(language.LanguageAssetError, match="pip install 'wordllama"):
        language.asset_root()


# ---------------------------------------------------------------------------------------------
# the embedding
# ---------------------------------------------------------------------------------------------
def test_embedding_table(table):
    assert table.shape == (language.VOCAB_SIZE, language.EMBED_DIM)
    assert table.dtype == np.float32 and np.isfinite(table).all()
    assert language.load_embedding() is table  # read once


def test_pooled_embedding_is_the_normalised_mean_of_word_tokens(table):
    rows = warnings.token_table()[:3]
    got = np.asarray(language.pooled_embedding(table, rows))
    for r, row in enumerate(rows):
        words = row[(row != language.PAD_ID) & (row != language.NUMBER_ID)]
        mean = table[words].astype(np.float64).mean(axis=0)
        np.testing.assert_allclose(got[r], mean / np.linalg.norm(mean), rtol=2e-5, atol=2e-6)
    np.testing.assert_allclose(np.linalg.norm(got, axis=-1), 1.0, rtol=1e-5)


def test_pooled_embedding_inside_jit_and_vmap_equals_outside(table):
    rows = warnings.token_table()
    outside = np.asarray(language.pooled_embedding(table, rows))
    fn = jax.jit(jax.vmap(language.pooled_embedding, in_axes=(None, 0)))
    np.testing.assert_allclose(np.asarray(fn(jnp.asarray(table), jnp.asarray(rows))), outside,
                               rtol=1e-5, atol=1e-6)  # fmt: skip


def test_pooled_embedding_gradient_is_finite_with_an_empty_row(table):
    small = jnp.asarray(table[:300])
    rows = jnp.asarray(
        [language.pad([10, 20, 30]), language.pad([])], jnp.int32
    )  # a text and an all-padding row

    def loss(t):
        return jnp.sum(language.pooled_embedding(t, rows) ** 2)

    g = jax.jit(jax.grad(loss))(small)
    assert np.isfinite(np.asarray(g)).all()
    assert np.abs(np.asarray(g)[[10, 20, 30]]).sum() > 0.0
    np.testing.assert_array_equal(np.asarray(language.pooled_embedding(small, rows[1])), 0.0)


def test_paraphrases_embed_closer_to_their_template_than_non_actionable_texts(table):
    """A sanity check that the loaded table is a real embedding, not noise: every family's
    low-ambiguity paraphrase is more similar to its canonical template than the mean
    non-actionable text is."""
    emb = np.asarray(language.pooled_embedding(table, warnings.token_table()))
    na = emb[list(warnings.non_actionable_text_ids())]
    for f in range(len(TEMPLATES)):
        para = emb[warnings.paraphrase_text_id(f)]
        assert emb[f] @ para > float(np.mean(na @ emb[f])), f


def test_mentions_finds_a_word_in_any_case_and_plural_inside_jit():
    """``language.mentions`` matches the word's token ids whatever sub-words the tokenizer
    splits a spelling into (``pedestrians`` is not ``pedestrian`` + ``s``), and nothing else."""
    from lantern_jax.types.language import mentions, pad, tokenize

    found = jax.jit(jax.vmap(lambda t: mentions(t, "pedestrian")))
    texts = ["A pedestrian may step out.", "PEDESTRIAN ahead", "Pedestrians near the bus stop.",
             "A cyclist may cut in.", "", "The ego lane is blocked."]  # fmt: skip
    rows = jnp.asarray(np.stack([pad(tokenize(t)) for t in texts]))
    assert np.asarray(found(rows)).tolist() == [True, True, True, False, False, False]
    with pytest.raises(ValueError, match="expected a word"):
        mentions(rows[0], " ")
