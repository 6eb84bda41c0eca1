"""A small MLP driving model written three ways, to run models from outside JAX in the rollout.

* :func:`numpy_model` — NumPy on the host, through :func:`lantern_jax.policies.host.host_policy`
  (the stand-in for a PyTorch model: same calling convention, NumPy in, NumPy out);
* :func:`jax_act` — the same model in JAX (the reference the host version must match);
* :func:`onnx_model` — the same model exported to ONNX and run by ONNX Runtime on the host
  (needs the optional packages ``onnx`` and ``onnxruntime``: ``pip install -e ".[onnx]"``).

The model maps the flat observation vector
(:func:`lantern_jax.policies.features.observation_vector`) to the two-number action
(acceleration, curvature) with one hidden layer::

    action = tanh(W2 . swish(W1 . x + b1) + b2)

Its weights are random (seeded): it shows the plumbing, it is not a good driver.

Run as a script to evaluate the NumPy and ONNX versions on two pairs per family::

    python examples/host_models.py
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.policies.base import Policy
from lantern_jax.policies.features import ACTION_SIZE, OBS_SIZE, observation_vector
from lantern_jax.policies.host import actions_to_waypoints, host_policy

HIDDEN = 32


def make_weights(seed: int = 0, hidden: int = HIDDEN) -> dict[str, np.ndarray]:
    """Random float32 weights; the bias of the first output asks for gentle acceleration."""
    rng = np.random.default_rng(seed)
    return {
        "w1": (rng.standard_normal((OBS_SIZE, hidden)) / np.sqrt(OBS_SIZE)).astype(np.float32),
        "b1": np.zeros(hidden, np.float32),
        "w2": (0.1 * rng.standard_normal((hidden, ACTION_SIZE))).astype(np.float32),
        "b2": np.asarray([0.2, 0.0], np.float32),
    }


def numpy_model(w: dict[str, np.ndarray]):
    """``fn(x: (B, OBS_SIZE)) -> (B, 2)`` in NumPy (float32 throughout)."""

    def fn(x: np.ndarray) -> np.ndarray:
        h = x @ w["w1"] + w["b1"]
        h = h / (1.0 + np.exp(-h))  # swish
        return np.tanh(h @ w["w2"] + w["b2"])

    return fn


def jax_act(w: dict[str, np.ndarray]):
    """The same model as a JAX policy ``act(params, obs) -> (10, 2)`` (weights closed over)."""
    wj = {k: jnp.asarray(v) for k, v in w.items()}

    def act(params, obs):
        del params
        h = jax.nn.swish(observation_vector(obs) @ wj["w1"] + wj["b1"])
        return actions_to_waypoints(jnp.tanh(h @ wj["w2"] + wj["b2"]), obs)

    return act


def jax_policy(w: dict[str, np.ndarray], name: str = "jax-mlp") -> Policy:
    """The JAX version as a policy with the same sensors as :func:`numpy_policy`."""
    return Policy(name, lambda key: {}, jax_act(w), "the same MLP in JAX", sensors=("warning",))


def numpy_policy(w: dict[str, np.ndarray], name: str = "numpy-mlp", fn=None) -> Policy:
    """The NumPy model (or ``fn``) as a host policy."""
    return host_policy(
        name,
        numpy_model(w) if fn is None else fn,
        out_shape=(ACTION_SIZE,),
        preprocess=observation_vector,
        postprocess=actions_to_waypoints,
        description="random MLP run on the host",
        sensors=("warning",),
    )


def onnx_bytes(w: dict[str, np.ndarray]) -> bytes:
    """The model as an ONNX graph (needs the ``onnx`` package)."""
    from onnx import TensorProto, helper, numpy_helper

    init = [numpy_helper.from_array(v, k) for k, v in w.items()]
    nodes = [
        helper.make_node("MatMul", ["x", "w1"], ["h0"]),
        helper.make_node("Add", ["h0", "b1"], ["h1"]),
        helper.make_node("Sigmoid", ["h1"], ["s"]),
        helper.make_node("Mul", ["h1", "s"], ["h2"]),
        helper.make_node("MatMul", ["h2", "w2"], ["o0"]),
        helper.make_node("Add", ["o0", "b2"], ["o1"]),
        helper.make_node("Tanh", ["o1"], ["action"]),
    ]
    graph = helper.make_graph(
        nodes,
        "lantern_mlp",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [None, OBS_SIZE])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, [None, ACTION_SIZE])],
        initializer=init,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    return model.SerializeToString()


def onnx_model(w: dict[str, np.ndarray]):
    """``fn(x) -> actions`` running the ONNX export with ONNX Runtime (CPU)."""
    import onnxruntime as ort

    session = ort.InferenceSession(onnx_bytes(w), providers=["CPUExecutionProvider"])
    return lambda x: session.run(["action"], {"x": np.asarray(x, np.float32)})[0]


def main() -> None:
    from lantern_jax.apps.evaluation import evaluate
    from lantern_jax.scenarios.suite import load_suite

    w = make_weights()
    policies = [numpy_policy(w)]
    try:
        policies.append(numpy_policy(w, "onnx-mlp", onnx_model(w)))
    except ImportError:
        print("onnx / onnxruntime not installed: evaluating the NumPy version only")
    result = evaluate(policies, suite=load_suite().subset(2))
    print(result.family_table.to_string(index=False))


if __name__ == "__main__":
    main()
