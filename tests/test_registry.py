"""Registry contract: ids, defaults, errors, metadata and entry-point plugins."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
import uuid
import warnings

import pytest

import vdtn_marl
import vdtn_marl.errors
from vdtn_marl.envs import registration as registry

NS = "vdtntest"


class DummyEnv:
    def __init__(self, num_vehicles: int = 4, impaired: bool = False, seed: int | None = None):
        self.num_vehicles = num_vehicles
        self.impaired = impaired
        self.seed = seed


@pytest.fixture(autouse=True)
def isolated_registry(monkeypatch):
    """Each test sees the built-ins plus what it registers; nothing leaks into other tests."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    monkeypatch.setattr(registry, "_SUPERSEDED", dict(registry._SUPERSEDED))
    monkeypatch.setattr(registry, "_PLUGINS_LOADED", registry._PLUGINS_LOADED)
    yield


def test_public_api_exported():
    for name in ("make", "list_envs", "register", "spec", "EnvSpec", "__version__"):
        assert hasattr(vdtn_marl, name), name
    assert isinstance(vdtn_marl.__version__, str) and vdtn_marl.__version__
    assert issubclass(vdtn_marl.UnknownEnvError, KeyError)
    assert issubclass(vdtn_marl.UnknownEnvError, LookupError)


def test_register_and_make_callable_entry_point():
    vdtn_marl.register(f"{NS}/dummy-v0", DummyEnv, num_vehicles=6, impaired=True)
    env = vdtn_marl.make(f"{NS}/dummy-v0")
    assert isinstance(env, DummyEnv)
    assert env.num_vehicles == 6 and env.impaired is True and env.seed is None


def test_make_kwargs_override_defaults_and_defaults_are_not_mutated():
    vdtn_marl.register(f"{NS}/dummy-v0", DummyEnv, num_vehicles=6, impaired=True)
    env = vdtn_marl.make(f"{NS}/dummy-v0", impaired=False, seed=3)
    assert (env.num_vehicles, env.impaired, env.seed) == (6, False, 3)
    assert vdtn_marl.spec(f"{NS}/dummy-v0").kwargs == {"num_vehicles": 6, "impaired": True}


def test_string_entry_point_is_lazy_and_merges_defaults():
    # A stdlib target keeps the test independent of the environment classes.
    vdtn_marl.register(f"{NS}/odict-v0", "collections:OrderedDict", a=1, b=2)
    assert vdtn_marl.make(f"{NS}/odict-v0", b=3) == {"a": 1, "b": 3}

    missing = f"vdtntest_missing_{uuid.uuid4().hex}"
    vdtn_marl.register(f"{NS}/missing-v0", f"{missing}:Env")  # not imported at register time
    assert missing not in sys.modules
    with pytest.raises(ImportError, match=f"{NS}/missing-v0"):
        vdtn_marl.make(f"{NS}/missing-v0")


def test_list_envs_sorted_and_contains_registered():
    vdtn_marl.register(f"{NS}/zz-v0", DummyEnv)
    vdtn_marl.register(f"{NS}/aa-v1", DummyEnv)
    ids = vdtn_marl.list_envs()
    assert ids == sorted(ids)
    assert {f"{NS}/zz-v0", f"{NS}/aa-v1"} <= set(ids)


def test_unknown_id_error_names_closest_match_and_known_ids():
    vdtn_marl.register(f"{NS}/platoon-dummy-v0", DummyEnv)
    with pytest.raises(vdtn_marl.UnknownEnvError) as info:
        vdtn_marl.make(f"{NS}/platoon-dumy-v0")
    msg = str(info.value)
    assert f"unknown env id '{NS}/platoon-dumy-v0'" in msg
    assert f"did you mean '{NS}/platoon-dummy-v0'?" in msg
    known = msg.split("known:", 1)[1]
    for env_id in vdtn_marl.list_envs():
        assert env_id in known
    with pytest.raises(KeyError):
        vdtn_marl.spec(f"{NS}/nothing-like-this-v7")


def test_unknown_id_without_close_match_has_no_suggestion():
    with pytest.raises(vdtn_marl.UnknownEnvError) as info:
        vdtn_marl.spec("zzzz/qqqqqqqqqqqqqqqqqqqqqqqqqqqq-v9")
    assert "did you mean" not in str(info.value)
    assert "known:" in str(info.value)


@pytest.mark.parametrize(
    "bad_id",
    ["dummy-v0", f"{NS}/dummy", f"{NS}/dummy-v", f"{NS}/dummy-0", f"/{NS}-v0", f"{NS}/a/b-v0", ""],
)
def test_bad_id_form_raises(bad_id):
    with pytest.raises(ValueError) as info:
        vdtn_marl.register(bad_id, DummyEnv)
    assert repr(bad_id) in str(info.value)
    assert "namespace/name-vN" in str(info.value)
    assert bad_id not in registry._REGISTRY


def test_bad_entry_point_string_raises():
    with pytest.raises(ValueError, match="module.path:ClassName"):
        vdtn_marl.register(f"{NS}/dummy-v0", "no_colon_here")


def test_duplicate_registration_raises_unless_override():
    vdtn_marl.register(f"{NS}/dummy-v0", DummyEnv, num_vehicles=3)
    with pytest.raises(ValueError, match="already registered"):
        vdtn_marl.register(f"{NS}/dummy-v0", DummyEnv, num_vehicles=5)
    assert vdtn_marl.spec(f"{NS}/dummy-v0").kwargs == {"num_vehicles": 3}
    vdtn_marl.register(f"{NS}/dummy-v0", DummyEnv, override=True, num_vehicles=5)
    assert vdtn_marl.make(f"{NS}/dummy-v0").num_vehicles == 5


def test_builtin_ids_cannot_be_silently_replaced():
    with pytest.raises(ValueError, match="already registered"):
        vdtn_marl.register("vdtn/platoon-control-v0", DummyEnv)


def test_spec_returns_metadata():
    returned = vdtn_marl.register(
        f"{NS}/dummy-v0",
        DummyEnv,
        agents="a_1..a_3",
        clocks={"a": 50, "b": 1},
        description="dummy env",
        data_source="none",
        impaired=True,
    )
    s = vdtn_marl.spec(f"{NS}/dummy-v0")
    assert s is returned
    assert isinstance(s, vdtn_marl.EnvSpec)
    assert s.id == f"{NS}/dummy-v0"
    assert s.entry_point is DummyEnv
    assert s.kwargs == {"impaired": True}
    assert s.agents == "a_1..a_3"
    assert s.clocks == {"a": 50, "b": 1}
    assert s.description == "dummy env"
    assert s.data_source == "none"
    with pytest.raises(AttributeError):  # frozen
        s.description = "changed"  # type: ignore[misc]


def test_bad_clock_period_raises():
    with pytest.raises(ValueError, match="clock period"):
        vdtn_marl.register(f"{NS}/dummy-v0", DummyEnv, clocks={"a": 0})


def test_builtin_specs_registered_with_metadata():
    """Metadata only: the classes behind the built-ins are tested with the environments."""
    builtin = {env_id for env_id in vdtn_marl.list_envs() if env_id.startswith("vdtn/")}
    assert builtin == {
        "vdtn/platoon-control-v0",  # no radio: its dynamics did not change with the channel
        "vdtn/platoon-control-impaired-v1",
        "vdtn/v2x-rra-v1",
        "vdtn/vdtn-joint-v1",
        "vdtn/platoon-control-central-v0",  # the Gymnasium single-agent faces
        "vdtn/platoon-control-impaired-central-v1",
    }
    assert set(vdtn_marl.list_envs(api="gymnasium")) == {
        "vdtn/platoon-control-central-v0",
        "vdtn/platoon-control-impaired-central-v1",
    }
    assert set(vdtn_marl.list_envs(api="pettingzoo")) == builtin - set(
        vdtn_marl.list_envs(api="gymnasium")
    )
    assert vdtn_marl.spec("vdtn/platoon-control-v0").kwargs == {"impaired": False}
    assert vdtn_marl.spec("vdtn/platoon-control-impaired-v1").kwargs == {"impaired": True}
    assert vdtn_marl.spec("vdtn/v2x-rra-v1").clocks == {"rra": 1}
    assert vdtn_marl.spec("vdtn/vdtn-joint-v1").clocks == {"vehicle": 50, "rra": 1}


def test_register_api_and_vector_entry_point():
    vdtn_marl.register(
        f"{NS}/dummy-v0",
        DummyEnv,
        api="gymnasium",
        vector_entry_point=lambda batch_size, **kw: ("batched", batch_size, kw),
        vector_kwargs={"impaired": True},
    )
    assert f"{NS}/dummy-v0" in vdtn_marl.list_envs(api="gymnasium")
    assert f"{NS}/dummy-v0" not in vdtn_marl.list_envs(api="pettingzoo")
    made = vdtn_marl.make(f"{NS}/dummy-v0", batch_size=5, seed=2)
    assert made == ("batched", 5, {"impaired": True, "seed": 2})
    assert isinstance(vdtn_marl.make(f"{NS}/dummy-v0"), DummyEnv)


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        ({"api": "rllib"}, "api='rllib'"),
        ({"vector_entry_point": "no_colon"}, "vector entry point 'no_colon'"),
    ],
)
def test_register_refuses_a_bad_api_or_vector_entry_point(kwargs, fragment):
    with pytest.raises(ValueError, match=re.escape(fragment)):
        vdtn_marl.register(f"{NS}/dummy-v0", DummyEnv, **kwargs)


def test_list_envs_refuses_an_unknown_api():
    with pytest.raises(ValueError, match="api='rllib'"):
        vdtn_marl.list_envs(api="rllib")


def test_batch_size_for_an_id_without_a_batched_face_names_those_with_one():
    vdtn_marl.register(f"{NS}/dummy-v0", DummyEnv)
    with pytest.raises(vdtn_marl.errors.ConfigError, match="batch_size=4") as info:
        vdtn_marl.make(f"{NS}/dummy-v0", batch_size=4)
    batched = [i for i in vdtn_marl.list_envs() if vdtn_marl.spec(i).vector_entry_point]
    assert batched and all(env_id in str(info.value) for env_id in batched)


def _superseded_builtins() -> dict[str, str]:
    """{old id: new id} of every built-in id that a newer version supersedes."""
    return {old: entry.new_id for old, entry in registry._SUPERSEDED.items()}


def test_every_bumped_builtin_supersedes_its_v0():
    superseded = _superseded_builtins()
    assert set(superseded.values()) == set(registry.VERSION_CHANGES)
    for env_id in vdtn_marl.list_envs():
        name, version = env_id.rsplit("-v", 1)
        if env_id.startswith("vdtn/") and int(version) > 0:
            assert superseded[f"{name}-v0"] == env_id
    assert "vdtn/platoon-control-v0" not in superseded  # still current
    assert not set(superseded) & set(vdtn_marl.list_envs())  # superseded ids are not listed


def test_superseded_id_raises_one_clear_deprecated_error():
    superseded = _superseded_builtins()
    assert superseded
    for old, new in superseded.items():
        for lookup in (vdtn_marl.make, vdtn_marl.spec):
            with pytest.raises(vdtn_marl.DeprecatedEnvError) as info:
                lookup(old)
            msg = str(info.value)
            assert msg.startswith(f"{old} is superseded by {new} (v1: "), msg
            assert "free-space floor" in msg and "v2v_pathloss_form='liang'" in msg
            assert "\n" not in msg
    assert issubclass(vdtn_marl.DeprecatedEnvError, vdtn_marl.UnknownEnvError)
    with pytest.raises(vdtn_marl.UnknownEnvError) as info:  # a version that never existed
        vdtn_marl.make("vdtn/v2x-rra-v7")
    assert not isinstance(info.value, vdtn_marl.DeprecatedEnvError)
    assert "did you mean 'vdtn/v2x-rra-v1'?" in str(info.value)


def test_v0_channel_from_a_v1_id_as_the_error_says():
    env = vdtn_marl.make("vdtn/v2x-rra-v1", seed=0, v2v_pathloss_form="liang")
    assert env.twin.params.radio.v2v_pathloss_form == "liang"
    assert vdtn_marl.make("vdtn/v2x-rra-v1", seed=0).twin.params.radio.v2v_pathloss_form == (
        "winner_b1"
    )


def test_a_superseded_id_can_be_registered_again():
    vdtn_marl.register("vdtn/v2x-rra-v0", DummyEnv, num_vehicles=3)
    assert vdtn_marl.make("vdtn/v2x-rra-v0").num_vehicles == 3


# --- third-party discovery through real entry points ------------------------------------------


def _write_plugin_dist(root, dist_name: str, entry_points: dict[str, str], modules: dict[str, str]):
    """Create ``<root>/<module>.py`` files and an installed-looking ``<dist>-0.1.dist-info``."""
    for mod_name, source in modules.items():
        (root / f"{mod_name}.py").write_text(textwrap.dedent(source))
    info = root / f"{dist_name}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist_name}\nVersion: 0.1\n")
    lines = ["[vdtn_marl.envs]"] + [f"{name} = {value}" for name, value in entry_points.items()]
    (info / "entry_points.txt").write_text("\n".join(lines) + "\n")


@pytest.fixture
def plugin_env(tmp_path, monkeypatch):
    """Unique module names (so sys.modules never serves a stale copy) and cleanup."""
    tag = uuid.uuid4().hex[:10]
    names = {"good": f"fakeplugin_good_{tag}", "broken": f"fakeplugin_broken_{tag}"}
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path, tag, names
    for name in names.values():
        sys.modules.pop(name, None)


GOOD_PLUGIN = """
    import vdtn_marl

    CALLS = 0


    class FakeEnv:
        def __init__(self, size=1):
            self.size = size


    def register_envs():
        global CALLS
        CALLS += 1
        vdtn_marl.register(
            "fakeplugin{tag}/fake-v0",
            __name__ + ":FakeEnv",
            agents="fake_1",
            clocks={{"fake": 10}},
            description="an env from a plugin",
            size=2,
        )
"""


def test_plugin_entry_point_is_discovered_once(plugin_env):
    root, tag, names = plugin_env
    _write_plugin_dist(
        root,
        f"fakeplugin{tag}",
        {"fake": f"{names['good']}:register_envs"},
        {names["good"]: GOOD_PLUGIN.format(tag=tag)},
    )
    env_id = f"fakeplugin{tag}/fake-v0"
    registry._reset_plugins_for_tests()
    with warnings.catch_warnings():
        warnings.simplefilter("error", vdtn_marl.PluginLoadWarning)
        ids = vdtn_marl.list_envs()
        assert env_id in ids
        assert "vdtn/vdtn-joint-v1" in ids  # built-ins are still there
        assert vdtn_marl.spec(env_id).description == "an env from a plugin"
        env = vdtn_marl.make(env_id, size=5)
        assert type(env).__name__ == "FakeEnv" and env.size == 5
        assert vdtn_marl.make(env_id).size == 2
    assert sys.modules[names["good"]].CALLS == 1  # loaded once, not on every call


def test_plugins_load_on_first_make_and_spec_too(plugin_env):
    root, tag, names = plugin_env
    _write_plugin_dist(
        root,
        f"fakeplugin{tag}",
        {"fake": f"{names['good']}:register_envs"},
        {names["good"]: GOOD_PLUGIN.format(tag=tag)},
    )
    registry._reset_plugins_for_tests()
    assert vdtn_marl.make(f"fakeplugin{tag}/fake-v0").size == 2
    registry._reset_plugins_for_tests()
    registry._REGISTRY.pop(f"fakeplugin{tag}/fake-v0")
    assert vdtn_marl.spec(f"fakeplugin{tag}/fake-v0").agents == "fake_1"


def test_broken_plugin_warns_and_registry_keeps_working(plugin_env):
    root, tag, names = plugin_env
    broken_src = """
        def register_envs():
            raise RuntimeError("boom from the broken plugin")
    """
    _write_plugin_dist(
        root,
        f"fakeplugin{tag}",
        {
            "broken": f"{names['broken']}:register_envs",
            "missing": f"fakeplugin_no_such_module_{tag}:register_envs",
            "fake": f"{names['good']}:register_envs",
        },
        {names["good"]: GOOD_PLUGIN.format(tag=tag), names["broken"]: broken_src},
    )
    registry._reset_plugins_for_tests()
    with pytest.warns(vdtn_marl.PluginLoadWarning) as record:
        ids = vdtn_marl.list_envs()
    messages = [str(w.message) for w in record]
    assert any("'broken'" in m and "boom from the broken plugin" in m for m in messages), messages
    assert any("'missing'" in m and "ModuleNotFoundError" in m for m in messages), messages
    # The healthy plugin of the same distribution and the built-ins still load.
    assert f"fakeplugin{tag}/fake-v0" in ids
    assert "vdtn/platoon-control-v0" in ids
    # No second round of warnings: loading happens once.
    with warnings.catch_warnings():
        warnings.simplefilter("error", vdtn_marl.PluginLoadWarning)
        vdtn_marl.list_envs()


def test_the_package_and_its_registry_import_neither_torch_nor_the_simulator():
    """``import vdtn_marl``, ``list_envs`` and ``spec`` stay light: the environments' modules
    load on ``make`` only (a fresh interpreter, as this one has torch already)."""
    code = (
        "import sys, vdtn_marl\n"
        "assert 'vdtn/vdtn-joint-v1' in vdtn_marl.list_envs()\n"
        "vdtn_marl.spec('vdtn/vdtn-joint-v1')\n"
        "print(sorted(m for m in ('torch', 'numpy', 'vdtn_marl.sim', 'vdtn_marl.envs.control')"
        " if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
