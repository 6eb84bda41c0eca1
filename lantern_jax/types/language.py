"""Warning texts as language: tokenisation and a pretrained token embedding, loaded offline.

Both come from files that ship inside the ``wordllama`` wheel on PyPI (MIT licence; version
0.4.x, https://github.com/dleemiller/WordLlama), read directly with ``tokenizers`` and
``safetensors`` — never through ``wordllama``'s own loader, which may try to download.  Nothing
is downloaded at run time.

=====================================================  ==========================================
file inside the installed ``wordllama`` package        what it is
=====================================================  ==========================================
``tokenizers/l2_supercat_tokenizer_config.json``       Hugging Face ``tokenizers`` JSON (1.8 MB):
                                                       the Llama-2 SentencePiece BPE tokenizer,
                                                       32,000 tokens, byte fallback
``weights/l2_supercat_256.safetensors``                one tensor ``embedding.weight``, (32000,
                                                       256) float16 (16.4 MB): WordLlama's
                                                       "L2 supercat" static token embedding,
                                                       truncated to 256 dimensions
=====================================================  ==========================================

Provenance and licence: the wheel (code and the two files) is distributed under the MIT licence
(``wordllama-*.dist-info/licenses/LICENSE``).  The embedding was trained by WordLlama's author
from the concatenated input-token embeddings of several Llama-2-family models, and the tokenizer
is Llama 2's; those upstream models are released by Meta under the Llama 2 Community License,
so check its terms before redistributing derived weights.

Token conventions (used by the observation and by every language policy):

* ``PAD_ID = 2`` (``</s>``, WordLlama's padding token) fills a text's row up to
  :data:`MAX_TOKENS`;
* ``NUMBER_ID = 0`` (``<unk>``, never produced by this byte-fallback tokenizer) is a **number
  token**: the number a text writes there is carried beside the ids, in a value channel aligned
  with the tokens (the tokenizer's number handling, see below);
* no beginning-of-sequence token (WordLlama embeds without special tokens).

**Numbers.**  A template says ``<FRONT_CAR_POS>`` where the delivered text writes the hazard's
position as ``(x, y)`` (metres, one decimal, the paper's form).  The tokenizer writes that
position as the ids of ``(``, a number token, ``,``, a number token and ``)``
(:func:`position_tokens`), and the value channel holds ``x`` and ``y`` at the two number tokens
(rounded to one decimal, exactly the digits the string shows) and zero everywhere else.  A text
that states no position has no number token and an all-zero value channel.  This is the only way
a number reaches a policy: there is no separate position field.

A text is tokenised piece by piece: the words between placeholders, stripped of the single space
that separates them from a placeholder, each go through the tokenizer as they are, so the ids of
every piece are exactly the tokenizer's output for that piece, and :func:`detokenize` gives the
text back (:func:`check_template` states the spacing rule that makes this exact: punctuation
may follow a placeholder directly, a word after one space).

The embedding is a plain array: :func:`pooled_embedding` (mean over a text's word tokens, then
unit length, as WordLlama's own inference pools) runs on NumPy outside ``jit`` and on a
``jax.Array`` table inside it.
"""

from __future__ import annotations

import functools
import importlib.util
import re
from collections.abc import Sequence
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

Array = jax.Array

ASSET_PACKAGE = "wordllama"
TOKENIZER_FILE = "tokenizers/l2_supercat_tokenizer_config.json"
WEIGHTS_FILE = "weights/l2_supercat_256.safetensors"
WEIGHTS_KEY = "embedding.weight"

VOCAB_SIZE = 32000  # tokens of the tokenizer and rows of the embedding
EMBED_DIM = 256  # columns of the embedding
MAX_TOKENS = 48  # fixed token length of a warning in the observation (longest bank text: 26)
PAD_ID = 2  # '</s>', WordLlama's padding token
NUMBER_ID = 0  # '<unk>': a number token, its value in the aligned value channel
PLACEHOLDER = "<FRONT_CAR_POS>"
NUMBER_DECIMALS = 1  # a written number shows one decimal (the paper's "(x, y)")
POSITION_PUNCTUATION = ("(", ",", ")")  # written around the two numbers of a position


class LanguageAssetError(FileNotFoundError):
    """The tokenizer or embedding file is missing or unreadable; the message names the file."""


def asset_root(root: str | Path | None = None) -> Path:
    """Folder holding the tokenizer and weights: ``root`` if given, else the installed
    ``wordllama`` package's own folder (found without importing it).

    Raises:
        LanguageAssetError: when ``wordllama`` is not installed.
    """
    if root is not None:
        return Path(root)
    spec = importlib.util.find_spec(ASSET_PACKAGE)
    if spec is None or not spec.submodule_search_locations:
        raise LanguageAssetError(
            f"the '{ASSET_PACKAGE}' package is not installed; it ships the tokenizer "
            f"({TOKENIZER_FILE}) and token embedding ({WEIGHTS_FILE}) that lantern_jax reads "
            f"offline: pip install '{ASSET_PACKAGE}>=0.4,<0.5'"
        )
    return Path(list(spec.submodule_search_locations)[0])


def _asset(root: str | Path | None, rel: str, what: str) -> Path:
    path = asset_root(root) / rel
    if not path.is_file():
        raise LanguageAssetError(
            f"{what} file not found: {path} (expected inside the installed '{ASSET_PACKAGE}' "
            f"package as {rel}; reinstall '{ASSET_PACKAGE}>=0.4,<0.5')"
        )
    return path


@functools.lru_cache(maxsize=4)
def load_tokenizer(root: str | None = None):
    """The ``tokenizers.Tokenizer`` of the embedding (cached per ``root``).

    Args:
        root: folder with ``tokenizers/...`` (default: the installed ``wordllama`` package).

    Raises:
        LanguageAssetError: naming the missing or unreadable file.
    """
    # deferred: loaded once, at the first text tokenized
    from tokenizers import Tokenizer

    path = _asset(root, TOKENIZER_FILE, "tokenizer")
    try:
        tok = Tokenizer.from_file(str(path))
    except Exception as e:
        raise LanguageAssetError(f"tokenizer file {path} cannot be read: {e}") from e
    if tok.get_vocab_size() != VOCAB_SIZE or tok.id_to_token(PAD_ID) != "</s>":
        raise LanguageAssetError(
            f"tokenizer file {path}: expected the {VOCAB_SIZE}-token Llama-2 vocabulary with "
            f"'</s>' at id {PAD_ID}, got {tok.get_vocab_size()} tokens"
        )
    return tok


@functools.lru_cache(maxsize=4)
def load_embedding(root: str | None = None) -> np.ndarray:
    """The token-embedding table, (VOCAB_SIZE, EMBED_DIM) float32 (stored as float16).

    Read once per ``root`` with ``safetensors`` (NumPy, no framework); pass it to
    :func:`pooled_embedding`, or ``jnp.asarray`` it into a policy's parameters.

    Raises:
        LanguageAssetError: naming the missing or unreadable file, or a wrong shape.
    """
    # deferred: loaded once, at the first embedding read
    from safetensors.numpy import load_file

    path = _asset(root, WEIGHTS_FILE, "embedding weights")
    try:
        tensors = load_file(str(path))
    except Exception as e:
        raise LanguageAssetError(f"embedding weights file {path} cannot be read: {e}") from e
    if WEIGHTS_KEY not in tensors:
        raise LanguageAssetError(
            f"embedding weights file {path}: no tensor {WEIGHTS_KEY!r} (has {sorted(tensors)})"
        )
    table = np.asarray(tensors[WEIGHTS_KEY], np.float32)
    if table.shape != (VOCAB_SIZE, EMBED_DIM):
        raise LanguageAssetError(
            f"embedding weights file {path}: {WEIGHTS_KEY} has shape {table.shape}, "
            f"expected {(VOCAB_SIZE, EMBED_DIM)}"
        )
    table.setflags(write=False)
    return table


#: Punctuation that may follow a placeholder directly (``"... near <FRONT_CAR_POS>; the ..."``,
#: as the paper's held-out cyclist paraphrase writes it); :func:`detokenize` glues a piece that
#: starts with one of them to the position before it.
GLUED_PUNCTUATION = ".,;:!?"


def check_template(text: str, placeholder: str = PLACEHOLDER) -> None:
    """Refuse a text that would not survive tokenisation unchanged.

    The rule: no leading or trailing whitespace; every placeholder separated from the word
    before it by exactly one space (or the start of the text), and followed by the end of the
    text, by :data:`GLUED_PUNCTUATION` directly, or by exactly one space and then a word, e.g.
    ``"The car at <FRONT_CAR_POS> is stopped."`` or ``"... near <FRONT_CAR_POS>; it ..."``, not
    ``"... at<FRONT_CAR_POS> ..."`` or ``"... at <FRONT_CAR_POS> ."``.

    Raises:
        ValueError: naming the problem.
    """
    if not isinstance(text, str) or not text.strip():
        raise ValueError("text: must be a non-empty string")
    if text != text.strip():
        raise ValueError(f"text: leading or trailing whitespace in {text!r}")
    for m in re.finditer(re.escape(placeholder), text):
        a, b = m.start(), m.end()
        before_ok = a == 0 or (text[a - 1] == " " and (a == 1 or not text[a - 2].isspace()))
        spaced = (
            b + 1 < len(text)
            and text[b] == " "
            and not text[b + 1].isspace()
            and text[b + 1] not in GLUED_PUNCTUATION
        )
        after_ok = b == len(text) or text[b] in GLUED_PUNCTUATION or spaced
        if not (before_ok and after_ok):
            raise ValueError(
                f"text: {placeholder} must be separated from the words by exactly one space "
                f"(punctuation may follow it directly) in {text!r}"
            )


@functools.lru_cache(maxsize=4)
def position_tokens(root: str | None = None) -> tuple[int, ...]:
    """The ids a written position ``(x, y)`` takes: ``(``, number, ``,``, number, ``)``.

    The punctuation goes through the tokenizer piece by piece, as the words of a template do;
    the two numbers are :data:`NUMBER_ID` (their values travel in the value channel).
    """
    tok = load_tokenizer(root)
    opening, comma, closing = (
        tuple(tok.encode(p, add_special_tokens=False).ids) for p in POSITION_PUNCTUATION
    )
    return (*opening, NUMBER_ID, *comma, NUMBER_ID, *closing)


def tokenize(text: str, root: str | None = None, placeholder: str = PLACEHOLDER) -> list[int]:
    """Token ids of a warning template; where ``placeholder`` stands, the ids of a written
    position (:func:`position_tokens`: two number tokens between punctuation).

    Args:
        text: the template (see :func:`check_template`); ``""`` is the empty text (no ids).
        root: asset folder (default: the installed ``wordllama`` package).

    Returns:
        The ids, unpadded (no special tokens).
    """
    if text == "":
        return []
    check_template(text, placeholder)
    tok = load_tokenizer(root)
    ids: list[int] = []
    for i, part in enumerate(text.split(placeholder)):
        if i > 0:
            ids += position_tokens(root)
        piece = part.strip()
        if piece:
            ids += tok.encode(piece, add_special_tokens=False).ids
    return ids


def number_slots(ids: Sequence[int]) -> list[int]:
    """Indices of the number tokens in ``ids`` (padded or not), in order."""
    return [i for i, v in enumerate(ids) if int(v) == NUMBER_ID]


def round_number(x: Array) -> Array:
    """A number as the text writes it: rounded to :data:`NUMBER_DECIMALS` decimals, in float32
    as the simulator holds it (jittable; half-way cases to even)."""
    scale = jnp.float32(10.0**NUMBER_DECIMALS)
    return jnp.round(jnp.asarray(x, jnp.float32) * scale) / scale


def format_number(x: float) -> str:
    """A number as a text writes it: :func:`round_number` (so the string and the value channel
    agree to the digit), :data:`NUMBER_DECIMALS` decimals, ``-0.0`` as ``0.0``."""
    return f"{float(round_number(x)) + 0.0:.{NUMBER_DECIMALS}f}"


def pad(ids: Sequence[int], length: int = MAX_TOKENS) -> np.ndarray:
    """(length,) int32: ``ids`` followed by :data:`PAD_ID`.

    Raises:
        ValueError: when ``ids`` is longer than ``length``.
    """
    if len(ids) > length:
        raise ValueError(f"tokens: {len(ids)} tokens exceed the fixed length {length}")
    out = np.full((length,), PAD_ID, np.int32)
    out[: len(ids)] = ids
    return out


def detokenize(
    ids: Sequence[int],
    values: Sequence[float] | None = None,
    root: str | None = None,
    placeholder: str = PLACEHOLDER,
) -> str:
    """The text back from its (possibly padded) token ids.

    Args:
        ids: token ids.
        values: the aligned value channel; with it a written position comes back as the
            delivered string writes it (``(12.3, 0.5)``), without it as ``placeholder`` (the
            template).
        root: asset folder (default: the installed ``wordllama`` package).
        placeholder: what stands for a position when ``values`` is not given.
    """
    tok = load_tokenizer(root)
    ids = [int(v) for v in ids]
    vals = [0.0] * len(ids) if values is None else [float(v) for v in values]
    pos = list(position_tokens(root))
    pieces: list[str] = []
    run: list[int] = []
    i = 0
    while i < len(ids):
        if ids[i] == PAD_ID:
            i += 1
            continue
        if ids[i : i + len(pos)] == pos:
            if run:
                pieces.append(tok.decode(run, skip_special_tokens=False))
            run = []
            nums = [vals[i + k] for k, t in enumerate(pos) if t == NUMBER_ID]
            pieces.append(
                placeholder
                if values is None
                else "(" + ", ".join(format_number(v) for v in nums) + ")"
            )
            i += len(pos)
            continue
        run.append(ids[i])
        i += 1
    if run:
        pieces.append(tok.decode(run, skip_special_tokens=False))
    text = pieces[0] if pieces else ""
    for piece in pieces[1:]:  # punctuation right after a position is glued to it
        glued = piece[:1] in GLUED_PUNCTUATION and text.endswith((")", placeholder))
        text += piece if glued else " " + piece
    return text


def shifted_rows(tokens: Array, width: int) -> Array:
    """(width, L) int32: row ``m`` is the token row shifted left by ``m``, -2 past its end (a
    window's ``m``-th token at every start; static slices, no gather).  Traceable."""
    n = tokens.shape[0]
    ext = jnp.concatenate([tokens, jnp.full((width,), -2, tokens.dtype)])
    return jnp.stack([ext[m : m + n] for m in range(width)])


@functools.cache
def word_spellings(word: str, root: str | None = None) -> np.ndarray:
    """(S, M) int32: the token ids of every spelling :func:`mentions` looks for, padded with -1:
    the word as given, lower case, capitalised and upper case, each also with ``s`` and ``es``
    (a plural splits into other sub-words: ``pedestrians`` is not ``pedestrian`` + ``s``)."""
    if not isinstance(word, str) or not word.strip():
        raise ValueError(f"mentions: expected a word, got {word!r}")
    w = word.strip()
    forms = [w, w.lower(), w[:1].upper() + w[1:].lower(), w.upper()]
    forms += [f + end for f in list(forms) for end in ("s", "es")]
    tok = load_tokenizer(root)
    rows = [tok.encode(f, add_special_tokens=False).ids for f in dict.fromkeys(forms)]
    rows = [r for r in rows if r]
    out = np.full((len(rows), max(map(len, rows))), -1, np.int32)
    for i, r in enumerate(rows):
        out[i, : len(r)] = r
    return out


def mentions(tokens: Array, word: str) -> Array:
    """() bool: the warning (its padded token ids, ``obs.warning_tokens``) mentions ``word``.

    Usable inside ``jit`` and ``vmap`` (``word`` is a Python string, tokenised once outside the
    trace).  Case (``pedestrian``, ``Pedestrian``, ``PEDESTRIAN``) and a plural in ``s`` or
    ``es`` are found, whatever sub-words the tokenizer splits each into::

        from lantern_jax.types.language import mentions
        slow = mentions(obs.warning_tokens, "pedestrian")    # in a policy's act

    Limits: it matches token ids, not meaning -- a synonym (``walker``), a negation (``no
    pedestrian``) or another inflection (``pedestrian's``) is not told apart; a word glued to
    the character before it (no space) is tokenised differently and missed; a word inside a
    longer one (``cyclist`` in ``cyclists``) is found.

    Args:
        tokens: (L,) int32, padded token ids.
        word: the word (one or several words, as written).
    """
    table = jnp.asarray(word_spellings(word))  # (S, M)
    k = table[:, :, None]  # (S, M, 1)
    match = (shifted_rows(tokens, table.shape[1])[None] == k) | (k < 0)  # (S, M, L)
    return jnp.any(jnp.all(match, axis=1))


def word_mask(tokens: Array) -> Array:
    """(..., L) bool: the word tokens of padded token rows (neither padding nor a number)."""
    return (tokens != PAD_ID) & (tokens != NUMBER_ID)


def token_embeddings(table: Array, tokens: Array) -> Array:
    """(..., L, D') rows of ``table`` (V, D') for padded token rows ``tokens`` (..., L) int32;
    ids outside the table are clipped to it (padding and numbers are rows like any other)."""
    return table[jnp.clip(tokens, 0, table.shape[0] - 1)]


def pooled_embedding(table: Array, tokens: Array, normalize: bool = True) -> Array:
    """Sentence embedding of padded token rows: the mean of the word-token embeddings.

    Works on NumPy arrays outside ``jit`` and on ``jax.Array`` inside it (and under ``vmap``);
    gradients with respect to ``table`` are finite (masked inputs, safe norms).  A row without
    any word token embeds to zeros.

    Args:
        table: (V, D) float, token-embedding table (:func:`load_embedding`).
        tokens: (..., L) int32, padded token ids (e.g. ``Observation.warning_tokens``).
        normalize: scale the mean to unit length (WordLlama's ``norm=True``).

    Returns:
        (..., D) float32.
    """
    table = jnp.asarray(table, jnp.float32)
    tokens = jnp.asarray(tokens, jnp.int32)
    mask = word_mask(tokens).astype(jnp.float32)
    emb = token_embeddings(table, tokens)  # (..., L, D)
    total = jnp.sum(emb * mask[..., None], axis=-2)
    count = jnp.sum(mask, axis=-1, keepdims=True)
    mean = total / jnp.maximum(count, 1.0)
    if not normalize:
        return mean
    sq = jnp.sum(mean * mean, axis=-1, keepdims=True)
    safe = jnp.where(sq > 1e-12, sq, 1.0)
    return jnp.where(sq > 1e-12, mean / jnp.sqrt(safe), 0.0)
