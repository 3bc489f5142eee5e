"""docker-compose.yml as the edge box's deployment, checked without Docker.

The file is validated against the Compose Specification's JSON schema (vendored in
deploy/schemas/, so the check runs offline), then against the code it deploys: the services of
``wz up``, their settings classes, their images (deploy/Dockerfile as each service's build args
make it) and their health probes.
"""

from __future__ import annotations

import copy
import hashlib
import importlib
import importlib.util
import inspect
import json
import re
import shlex
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml
import zenoh
from pydantic import BaseModel
from pydantic_settings import BaseSettings

from wz_cli.stack import ROUTER, STACK, ServiceSpec
from wz_gateway.auth import new_secret
from wz_shared.settings import BusSettings, ServiceSettings

ROOT = Path(__file__).resolve().parents[2]
COMPOSE_FILE = ROOT / "docker-compose.yml"
DOCKERFILE = ROOT / "deploy" / "Dockerfile"
SCHEMA_FILE = ROOT / "deploy" / "schemas" / "compose-spec.json"

#: A stand-in for the variable .env must set; the other ${VAR:-default} take their defaults.
STAND_IN_ENV = {"WZ_GATEWAY_API_KEYS": f"admin:{new_secret()}"}

#: Each compose service's settings class (the one its node builds in main()).
SETTINGS_CLASSES = {
    "router": "wz_shared.settings:ServiceSettings",
    "simulator": "wz_simulator.settings:SimulatorSettings",
    "lidar-detector": "wz_lidar_detector.settings:LidarDetectorSettings",
    "camera-detector": "wz_camera_detector.settings:CameraDetectorSettings",
    "fusion-tracker": "wz_fusion_tracker.settings:FusionTrackerSettings",
    "alert-service": "wz_alert_service.settings:AlertServiceSettings",
    "gateway": "wz_gateway.settings:GatewaySettings",
    "drivers": "wz_drivers.settings:DriversSettings",
    "device-driver": "wz_drivers.device_driver:DeviceDriverSettings",
}

#: Users that are root inside a container.
ROOT_USERS = {"root", "0", "0:0", "root:root"}
RESTART_POLICIES = {"always", "unless-stopped", "on-failure"}


# --- loading ------------------------------------------------------------------------------


def load_compose() -> dict[str, Any]:
    """docker-compose.yml as YAML gives it (merge keys resolved, variables not)."""
    with COMPOSE_FILE.open(encoding="utf-8") as stream:
        loaded = yaml.safe_load(stream)
    assert isinstance(loaded, dict)
    return loaded


_VARIABLE = re.compile(
    r"\$\$|\$\{(?P<name>[A-Za-z_][A-Za-z0-9_]*)(?:(?P<op>:?[-?])(?P<arg>[^}]*))?\}"
)


def interpolate(value: Any, env: Mapping[str, str]) -> Any:
    """``value`` with ``${VAR}``, ``${VAR:-default}`` and ``${VAR:?error}`` replaced as Compose
    replaces them (``$$`` is a literal ``$``).

    Raises
    ------
    KeyError
        For a required variable (``:?``) that ``env`` lacks.
    """
    if isinstance(value, dict):
        return {key: interpolate(item, env) for key, item in value.items()}
    if isinstance(value, list):
        return [interpolate(item, env) for item in value]
    if not isinstance(value, str):
        return value

    def replace(match: re.Match[str]) -> str:
        if match.group(0) == "$$":
            return "$"
        name, op, arg = match.group("name"), match.group("op"), match.group("arg")
        given = env.get(name)
        if op in (":-", "-"):
            return given if given else arg
        if op in (":?", "?"):
            if not given:
                raise KeyError(f"{name}: {arg}")
            return given
        return given or ""

    return _VARIABLE.sub(replace, value)


_ARG_REFERENCE = re.compile(
    r"\$(?:\{(?P<braced>[A-Za-z_][A-Za-z0-9_]*)\}|(?P<bare>[A-Za-z_][A-Za-z0-9_]*))"
)


def _substitute(text: str, values: Mapping[str, str]) -> str:
    """``text`` with ``$NAME`` and ``${NAME}`` of ``values`` replaced; other names kept."""
    return _ARG_REFERENCE.sub(
        lambda match: values.get(match["braced"] or match["bare"], match.group(0)), text
    )


@dataclass
class Dockerfile:
    """A Dockerfile's instructions as one image's build sees them: grouped by stage,
    continuation lines joined, and its ``ARG`` values (the defaults, or the build args compose
    gives) put in where the stage has declared them, as Docker and the build's shell do."""

    path: Path
    build_args: Mapping[str, str] = field(default_factory=dict)
    stages: list[list[tuple[str, str]]] = field(default_factory=list)
    #: Every ARG name the file declares (a build arg it does not declare is never used).
    declared_args: set[str] = field(default_factory=set)

    @classmethod
    def read(cls, path: Path, build_args: Mapping[str, str] | None = None) -> Dockerfile:
        dockerfile = cls(path, dict(build_args or {}))
        global_args: dict[str, str] = {}  # before the first FROM: seen by FROM lines only
        scope: dict[str, str] = {}
        logical = ""
        for raw in path.read_text(encoding="utf-8").splitlines():
            line = raw.strip()
            if not logical and (not line or line.startswith("#")):
                continue
            if line.startswith("#"):
                continue
            if line.endswith("\\"):
                logical += line[:-1] + " "
                continue
            logical += line
            instruction, _, rest = logical.partition(" ")
            instruction, rest, logical = instruction.upper(), rest.strip(), ""
            if instruction == "ARG":
                name, has_default, default = rest.partition("=")
                dockerfile.declared_args.add(name)
                if name in dockerfile.build_args:
                    value = dockerfile.build_args[name]
                elif has_default:
                    value = shlex.split(default)[0] if shlex.split(default) else ""
                else:
                    value = global_args.get(name, "")
                (scope if dockerfile.stages else global_args)[name] = value
                continue
            if instruction == "FROM":
                dockerfile.stages.append([])
                scope = {}
                rest = _substitute(rest, global_args)
            elif instruction == "ENV":  # Docker substitutes each KEY=value word on its own
                rest = " ".join(shlex.quote(_substitute(word, scope)) for word in shlex.split(rest))
            elif not rest.startswith("["):  # exec form (JSON) is taken as written
                rest = _substitute(rest, scope)
            dockerfile.stages[-1].append((instruction, rest))
        return dockerfile

    def instructions(self, name: str, stage: int = -1) -> list[str]:
        return [rest for instruction, rest in self.stages[stage] if instruction == name]

    @property
    def final(self) -> list[tuple[str, str]]:
        return self.stages[-1]

    def env(self) -> dict[str, str]:
        """The final stage's ENV values."""
        values: dict[str, str] = {}
        for rest in self.instructions("ENV"):
            for word in shlex.split(rest):
                key, sep, value = word.partition("=")
                assert sep, f"{self.path}: ENV {rest!r}: use KEY=value"
                values[key] = value
        return values

    def exec_form(self, name: str) -> list[str]:
        """The final stage's last ``name`` (CMD, ENTRYPOINT) in exec (JSON) form."""
        found = self.instructions(name)
        assert found, f"{self.path} has no {name}"
        words = json.loads(found[-1])
        assert isinstance(words, list)
        return [str(word) for word in words]


@dataclass
class Service:
    """One compose service, interpolated, with what its image brings."""

    name: str
    config: dict[str, Any]
    dockerfile: Dockerfile

    @property
    def environment(self) -> dict[str, str]:
        """The container's environment: the image's ENV, then compose's ``environment``."""
        env = self.dockerfile.env()
        declared = self.config.get("environment", {})
        assert isinstance(declared, dict), f"{self.name}: write environment as a mapping"
        env.update({key: "" if value is None else str(value) for key, value in declared.items()})
        return env

    @property
    def spec(self) -> ServiceSpec:
        return {spec.name: spec for spec in (ROUTER, *STACK)}[self.name]


@pytest.fixture(scope="module")
def compose() -> dict[str, Any]:
    interpolated = interpolate(load_compose(), STAND_IN_ENV)
    assert isinstance(interpolated, dict)
    return interpolated


def image_of(compose_file: Path, name: str, config: Mapping[str, Any]) -> Dockerfile:
    """The Dockerfile of a compose service, read with the service's build args."""
    build = config.get("build")
    assert isinstance(build, dict), f"{name}: build: {{context, dockerfile, args}} expected"
    path = (compose_file.parent / build.get("context", ".") / build["dockerfile"]).resolve()
    assert path == DOCKERFILE, f"{name}: every image is built from {DOCKERFILE.relative_to(ROOT)}"
    args = build.get("args", {})
    assert isinstance(args, dict), f"{name}: write build args as a mapping"
    return Dockerfile.read(path, {key: str(value) for key, value in args.items()})


#: Third-party services of the monitoring profile (published images, not ours to build).
MONITORING = ("prometheus", "grafana")


@pytest.fixture(scope="module")
def services(compose: dict[str, Any]) -> dict[str, Service]:
    """The project's own services (built from deploy/Dockerfile)."""
    return {
        name: Service(name, config, image_of(COMPOSE_FILE, name, config))
        for name, config in compose["services"].items()
        if name not in MONITORING
    }


def test_the_monitoring_profile_runs_prometheus_and_grafana_on_the_shipped_files(
    compose: dict[str, Any],
) -> None:
    """Pinned images, loopback ports, the shipped config, rules and dashboard mounted (each
    file there), limits; every other service scrapes on WZ_METRICS_PORT."""
    assert "monitoring" in compose["x-profiles"]
    for name in MONITORING:
        config = compose["services"][name]
        assert config["profiles"] == ["monitoring"]
        image = config["image"]
        assert ":" in image and not image.endswith(":latest"), f"{name}: pin the image"
        assert all(str(port).startswith("127.0.0.1:") for port in config["ports"])
        assert config["deploy"]["resources"]["limits"]["memory"]
        for volume in config["volumes"]:
            source = volume.split(":")[0]
            if source.startswith("./"):
                assert (ROOT / source).exists(), f"{name}: {source} is not in the repository"
    prometheus_mounts = " ".join(compose["services"]["prometheus"]["volumes"])
    assert "deploy/monitoring/prometheus.yml" in prometheus_mounts
    assert "deploy/monitoring/rules.yml" in prometheus_mounts
    for name, config in compose["services"].items():
        if name in MONITORING or name in ("router", "gateway"):
            continue
        assert config["environment"]["WZ_METRICS_PORT"] == "9464", name


def schema_errors(document: Any) -> list[str]:
    schema = json.loads(SCHEMA_FILE.read_text(encoding="utf-8"))
    validator = jsonschema.Draft7Validator(schema)
    return [
        f"{'/'.join(str(part) for part in error.absolute_path)}: {error.message}"
        for error in validator.iter_errors(document)
    ]


# --- the schema ---------------------------------------------------------------------------


def test_schema_is_the_vendored_file() -> None:
    """The file is the Compose Specification's schema, unedited (size and digest recorded in
    deploy/schemas/README.md), and a valid draft-07 schema."""
    data = SCHEMA_FILE.read_bytes()
    readme = (SCHEMA_FILE.parent / "README.md").read_text(encoding="utf-8")
    assert f"{len(data):,} bytes" in readme
    assert hashlib.sha256(data).hexdigest() in readme
    schema = json.loads(data)
    assert schema["title"] == "Compose Specification"
    jsonschema.Draft7Validator.check_schema(schema)


def test_compose_file_is_valid_compose() -> None:
    """As written and after variable substitution."""
    raw = load_compose()
    assert schema_errors(raw) == []
    assert schema_errors(interpolate(raw, STAND_IN_ENV)) == []


@pytest.mark.parametrize(
    ("where", "bad_value"),
    [
        (("services", "gateway", "restart_policy"), "always"),  # swarm's word, not a key here
        (("services", "gateway", "depends_on", "router"), {"condition": "healthy"}),
        (("services", "gateway", "deploy", "resources", "limits", "memory"), 1024),
        (("volumes", "gateway-data"), ["not", "a", "mapping"]),
    ],
)
def test_schema_rejects_a_broken_file(where: tuple[str, ...], bad_value: Any) -> None:
    """The validation can fail: each mistake above is caught."""
    broken = copy.deepcopy(load_compose())
    node = broken
    for key in where[:-1]:
        node = node[key]
    node[where[-1]] = bad_value
    assert schema_errors(broken) != []


def test_a_required_variable_without_a_value_is_an_error() -> None:
    """Compose refuses to start without WZ_GATEWAY_API_KEYS; so does our substitution."""
    with pytest.raises(KeyError, match="WZ_GATEWAY_API_KEYS"):
        interpolate(load_compose(), {})


# --- the services are the stack of `wz up` ------------------------------------------------


def test_services_are_the_stack_of_wz_up(services: dict[str, Service]) -> None:
    assert set(services) == {ROUTER.name} | {spec.name for spec in STACK}


#: The image's ENTRYPOINT: a shell that becomes SERVICE_COMMAND (the build arg COMMAND, split
#: into words) with compose's ``command:`` as its arguments.
ENTRYPOINT = ["/bin/sh", "-c", 'exec $SERVICE_COMMAND "$@"', "sh"]


def program(service: Service) -> list[str]:
    """What the container runs: the image's COMMAND, then compose's ``command:``."""
    assert service.dockerfile.exec_form("ENTRYPOINT") == ENTRYPOINT, service.name
    assert "entrypoint" not in service.config, f"{service.name}: the image's entrypoint is bypassed"
    assert not service.dockerfile.instructions("CMD"), "compose's command: gives the arguments"
    command = service.config.get("command", [])
    assert isinstance(command, list), f"{service.name}: command in exec (list) form"
    return shlex.split(service.dockerfile.env()["SERVICE_COMMAND"]) + [str(w) for w in command]


def test_each_image_runs_its_stack_module(services: dict[str, Service]) -> None:
    for spec in STACK:
        assert program(services[spec.name]) == ["python", "-m", spec.module], spec.name
    router = program(services[ROUTER.name])
    assert router[0] == "wz"
    assert router[1 : 1 + len(ROUTER.args)] == list(ROUTER.args)
    assert ROUTER.module == "wz_cli.main"


def _workspace_members() -> dict[str, dict[str, Any]]:
    """The workspace's members: project name -> its ``[project]`` table."""
    root = tomllib.loads((ROOT / "pyproject.toml").read_text("utf-8"))
    members: dict[str, dict[str, Any]] = {}
    for pattern in root["tool"]["uv"]["workspace"]["members"]:
        for folder in sorted(ROOT.glob(pattern)):
            if (folder / "pyproject.toml").is_file():
                project = tomllib.loads((folder / "pyproject.toml").read_text("utf-8"))["project"]
                members[str(project["name"])] = project
    return members


def test_build_args_name_a_member_and_its_program(services: dict[str, Service]) -> None:
    """PACKAGE is a workspace member; COMMAND runs a module or a script that member installs;
    every build arg given is one the Dockerfile declares (Docker ignores any other)."""
    members = _workspace_members()
    for service in services.values():
        image = service.dockerfile
        assert set(image.build_args) <= image.declared_args, (
            f"{service.name}: build args {set(image.build_args) - image.declared_args} are unused"
        )
        package = image.build_args.get("PACKAGE", "")
        assert package in members, f"{service.name}: PACKAGE={package!r} is no workspace member"
        command = shlex.split(image.build_args.get("COMMAND", ""))
        if command[:2] == ["python", "-m"]:
            assert _distribution_of(command[2])[0] == package, (
                f"{service.name}: {command[2]} is not in {package}"
            )
        else:
            scripts = members[package].get("scripts", {})
            assert command[0] in scripts, f"{service.name}: {package} installs no {command[0]}"
            module = scripts[command[0]].split(":")[0]
            assert module == service.spec.module, service.name


def _distribution_of(module: str) -> tuple[str, list[str]]:
    """The workspace member that holds ``module``: its project name and dependencies."""
    found = importlib.util.find_spec(module)
    assert found is not None and found.origin is not None, f"{module} is not installed"
    for folder in Path(found.origin).parents:
        if (folder / "pyproject.toml").is_file():
            project = tomllib.loads((folder / "pyproject.toml").read_text("utf-8"))["project"]
            dependencies = [
                re.split(r"[\s<>=!~\[;]", dep, maxsplit=1)[0]
                for dep in project.get("dependencies", [])
            ]
            return str(project["name"]), dependencies
    raise AssertionError(f"no pyproject.toml above {found.origin}")


def _synced_package(dockerfile: Dockerfile) -> str:
    syncs = [rest for rest in dockerfile.instructions("RUN", stage=0) if "uv sync" in rest]
    assert len(syncs) == 1, f"{dockerfile.path}: one `uv sync` in the build stage"
    words = shlex.split(syncs[0])
    return words[words.index("--package") + 1]


# --- Dockerfiles --------------------------------------------------------------------------


def test_dockerfile_without_build_args_is_refused() -> None:
    """Without PACKAGE (build stage) or COMMAND (run stage) the build stops at that stage's
    first step, with a message, instead of an image that runs nothing."""
    bare = Dockerfile.read(DOCKERFILE)
    given = Dockerfile.read(DOCKERFILE, {"PACKAGE": "wz-cli", "COMMAND": "wz"})
    for stage in (0, -1):
        assert bare.instructions("RUN", stage=stage)[0].startswith('test -n "" || ')
        assert given.instructions("RUN", stage=stage)[0].startswith('test -n "wz')


def test_the_per_service_dockerfiles_are_gone() -> None:
    """One Dockerfile: one a service folder kept for itself would drift from it."""
    found = [
        path
        for top in ("shared", "services", "cli", "eval", "deploy", "tests")
        for path in (ROOT / top).rglob("*Dockerfile*")
    ]
    assert found == [DOCKERFILE]
    assert not (ROOT / "Dockerfile").exists()


def test_dockerfiles_are_multi_stage_non_root_and_locked(services: dict[str, Service]) -> None:
    for service in services.values():
        dockerfile = service.dockerfile
        where = f"{service.name} ({dockerfile.path.relative_to(ROOT)})"
        assert len(dockerfile.stages) >= 2, f"{where}: build and run stages"
        build_stage = shlex.split(dockerfile.instructions("FROM", stage=0)[0])
        assert len(build_stage) == 3 and build_stage[1].upper() == "AS", f"{where}: name stage 1"
        copies = dockerfile.instructions("COPY")
        assert any(c.startswith(f"--from={build_stage[2]} ") for c in copies), (
            f"{where}: the run stage copies the environment built in stage {build_stage[2]!r}"
        )
        assert not any(
            "uv sync" in rest or "pip install" in rest for rest in dockerfile.instructions("RUN")
        ), f"{where}: no build tools"
        users = dockerfile.instructions("USER")
        assert users and users[-1] not in ROOT_USERS, f"{where}: runs as root"
        assert "user" not in service.config or service.config["user"] not in ROOT_USERS, where
        assert any("uv.lock" in c for c in dockerfile.instructions("COPY", stage=0)), where
        sync = next(r for r in dockerfile.instructions("RUN", stage=0) if "uv sync" in r)
        assert {"--frozen", "--locked"} & set(shlex.split(sync)), f"{where}: sync from uv.lock"
        assert "--no-dev" in shlex.split(sync), f"{where}: no dev tools in the image"


def test_each_image_installs_the_package_of_its_module(services: dict[str, Service]) -> None:
    for service in services.values():
        project, _ = _distribution_of(service.spec.module)
        assert _synced_package(service.dockerfile) == project, service.name


# --- health -------------------------------------------------------------------------------


def _probe(service: Service) -> list[str]:
    healthcheck = service.config.get("healthcheck")
    assert healthcheck, f"{service.name} has no healthcheck"
    assert not healthcheck.get("disable"), service.name
    test = healthcheck["test"]
    assert isinstance(test, list) and test[0] == "CMD", f"{service.name}: exec-form test"
    return [str(word) for word in test[1:]]


def test_every_service_has_a_real_health_probe(services: dict[str, Service]) -> None:
    """Each probe runs something that exists in the image and looks where the service is. The
    image has no HEALTHCHECK of its own: compose's is the only one, so none can disagree."""
    for service in services.values():
        assert not service.dockerfile.instructions("HEALTHCHECK"), service.name
        probe = _probe(service)
        assert probe[0] == "python", service.name
        if probe[1] == "-m":
            module = probe[2]
            assert module == "wz_shared.health", f"{service.name}: unknown probe {module}"
            project, dependencies = _distribution_of(service.spec.module)
            assert "wz-shared" in (project, *dependencies), service.name
            health_file = service.environment.get("WZ_HEALTH_FILE")
            assert probe[3] == health_file, f"{service.name}: probes a file the node never touches"
            max_age_s = float(probe[probe.index("--max-age-s") + 1])
            status_period_s = float(service.environment.get("WZ_STATUS_PERIOD_S", "1.0"))
            assert max_age_s >= 3 * status_period_s, f"{service.name}: a late status is unhealthy"
            stall_after_s = float(service.environment.get("WZ_STALL_AFTER_S", "5.0"))
            # A blocked loop unhealthy within 10 s (the trust issue), a slow one not at all.
            assert stall_after_s < max_age_s <= 10.0, service.name
        else:
            assert probe[1] == "-c", service.name
            compile(probe[2], f"<{service.name} healthcheck>", "exec")


#: The third-party images of the monitoring profile and the endpoint each one's probe asks.
THIRD_PARTY_HEALTH = {"prometheus": "/-/healthy", "grafana": "/api/health"}


def test_every_compose_service_has_a_healthcheck_the_third_party_ones_too() -> None:
    """Every service of every profile: `podman ps` / `docker compose ps` shows each one's
    health, and a `depends_on: service_healthy` can name any of them."""
    document = yaml.safe_load(COMPOSE_FILE.read_text(encoding="utf-8"))
    for name, config in document["services"].items():
        healthcheck = config.get("healthcheck")
        assert healthcheck and not healthcheck.get("disable"), f"{name} has no healthcheck"
        test = healthcheck["test"]
        assert isinstance(test, list) and test[0] == "CMD", name
        if name in THIRD_PARTY_HEALTH:
            assert test[1] == "wget" and test[-1].endswith(THIRD_PARTY_HEALTH[name]), name
    assert set(THIRD_PARTY_HEALTH) <= set(document["services"])
    grafana_needs = document["services"]["grafana"]["depends_on"]
    assert grafana_needs["prometheus"]["condition"] == "service_healthy"


def _mounted(service: Service, container_path: str) -> Path:
    """The file of this repository that ``service`` sees at ``container_path``."""
    for entry in service.config.get("volumes", []):
        source, target = str(entry).split(":")[:2]
        if container_path == target or container_path.startswith(target + "/"):
            return COMPOSE_FILE.parent / source / container_path.removeprefix(target).lstrip("/")
    raise AssertionError(f"{service.name} does not mount {container_path}")


def _zenoh_endpoints(path: Path, which: str) -> list[str]:
    return list(json.loads(zenoh.Config.from_file(str(path)).get_json(f"{which}/endpoints")))


def test_router_probe_targets_the_port_it_listens_on(services: dict[str, Service]) -> None:
    """The router listens (its zenoh config, as mounted) on the port its probe and the
    published port name; every service's zenoh config (as mounted) connects to it."""
    router = services[ROUTER.name]
    command = router.config["command"]
    assert "--listen" not in command  # the config file says it
    (listen,) = _zenoh_endpoints(_mounted(router, command[command.index("--config") + 1]), "listen")
    port = int(listen.rsplit(":", 1)[1])
    assert listen == f"tls/0.0.0.0:{port}"
    assert f"('127.0.0.1', {port})" in _probe(router)[2]
    assert any(str(p).endswith(f":{port}") for p in router.config["ports"])
    for service in services.values():
        if service.name != ROUTER.name:
            assert not {"WZ_BUS_MODE", "WZ_BUS_CONNECT_ENDPOINTS"} & set(service.environment)
            config = _mounted(service, service.environment["WZ_BUS_CONFIG_FILE"])
            assert _zenoh_endpoints(config, "connect") == [f"tls/{ROUTER.name}:{port}"]
            assert json.loads(zenoh.Config.from_file(str(config)).get_json("mode")) == "client"


def test_gateway_probe_asks_readiness_on_the_gateway_port(
    services: dict[str, Service], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from wz_gateway.app import create_app
    from wz_gateway.settings import GatewaySettings
    from wz_gateway.storage import Storage
    from wz_shared.site import load_site

    gateway = services["gateway"]
    url = re.search(r"http://127\.0\.0\.1:(\d+)(/\w+)", _probe(gateway)[2])
    assert url is not None
    port, path = int(url.group(1)), url.group(2)
    _use_environment(monkeypatch, gateway.environment)
    settings = GatewaySettings()
    assert settings.port == port
    assert any(str(p).endswith(f":{port}") for p in gateway.config["ports"])
    settings = settings.model_copy(update={"data_dir": tmp_path})
    storage = Storage.open(settings.resolved_database_url())
    try:
        app = create_app(settings, storage, site=load_site(ROOT / "deploy/sites/us75-lincoln.yaml"))
        assert path in app.openapi()["paths"]
    finally:
        storage.close()


# --- start order, restarts, limits --------------------------------------------------------


def test_dependencies_wait_for_healthy_services(services: dict[str, Service]) -> None:
    for service in services.values():
        depends_on = service.config.get("depends_on", {})
        assert isinstance(depends_on, dict), f"{service.name}: depends_on as a mapping"
        if service.name != ROUTER.name:
            assert ROUTER.name in depends_on, f"{service.name} starts before the router"
        for target, condition in depends_on.items():
            assert condition["condition"] == "service_healthy", f"{service.name} -> {target}"
            assert services[target].config.get("healthcheck"), target
            # A dependency in a profile that is off would stop this service from starting.
            assert set(services[target].config.get("profiles", [])) <= set(
                service.config.get("profiles", [])
            ), f"{service.name} depends on {target}, which a profile may leave out"


def test_restart_policies(services: dict[str, Service]) -> None:
    for service in services.values():
        assert service.config.get("restart") in RESTART_POLICIES, service.name


def test_logs_are_rotated(services: dict[str, Service]) -> None:
    for service in services.values():
        logging_config = service.config.get("logging", {})
        assert logging_config.get("driver") == "json-file", service.name
        assert {"max-size", "max-file"} <= set(logging_config.get("options", {})), service.name


_UNITS = {"": 1, "b": 1, "k": 2**10, "m": 2**20, "g": 2**30}


def memory_bytes(text: str) -> int:
    match = re.fullmatch(r"(\d+(?:\.\d+)?)\s*([bkmg]?)b?", str(text).strip().lower())
    assert match, f"memory {text!r}"
    return int(float(match.group(1)) * _UNITS[match.group(2)])


def test_memory_bytes() -> None:
    assert memory_bytes("256M") == 256 * 2**20
    assert memory_bytes("1g") == 2**30
    assert memory_bytes("1536m") == 1536 * 2**20


def test_limits_fit_the_edge_box(compose: dict[str, Any], services: dict[str, Service]) -> None:
    box = compose["x-edge-box"]
    budget = memory_bytes(box["memory"]) - memory_bytes(box["reserved_for_host"])
    total = 0
    for service in services.values():
        limits = service.config.get("deploy", {}).get("resources", {}).get("limits", {})
        assert {"cpus", "memory"} <= set(limits), f"{service.name}: cpus and memory limits"
        assert 0 < float(limits["cpus"]) <= float(box["cpus"]), service.name
        assert memory_bytes(limits["memory"]) >= 128 * 2**20, f"{service.name}: too small to run"
        total += memory_bytes(limits["memory"])
    assert total <= budget, (
        f"limits add up to {total / 2**30:.2f} GiB, the box has {budget / 2**30:.2f}"
    )


# --- profiles, volumes, ports -------------------------------------------------------------


def test_profiles_separate_simulation_from_the_field(
    compose: dict[str, Any], services: dict[str, Service]
) -> None:
    declared = compose["x-profiles"]
    assert {"simulation", "field"} <= set(declared)
    assert services["simulator"].config.get("profiles") == ["simulation"]
    for service in services.values():
        used = set(service.config.get("profiles", []))
        assert used <= set(declared), f"{service.name}: undeclared profile {used - set(declared)}"
        if service.name == "drivers":  # the field's sensors, in the simulator's place
            assert used == {"field"}
        elif service.name == "device-driver":  # a trailer with a message sign on its network
            assert used == {"sign"}
        elif service.name != "simulator":
            # The router and the pipeline run whatever feeds them.
            assert not used, f"{service.name} would not run in the field"


def _named_volumes(service: Service) -> dict[str, str]:
    """Named volume -> target path, from the short syntax."""
    mounts: dict[str, str] = {}
    for entry in service.config.get("volumes", []):
        source, target = str(entry).split(":")[:2]
        if not source.startswith((".", "/", "~")):
            mounts[source] = target
    return mounts


def test_named_volumes_are_declared_and_writable_by_the_image_user(
    compose: dict[str, Any], services: dict[str, Service]
) -> None:
    """A new named volume copies its folder's owner from the image: a non-root service can
    write to it only if the Dockerfile made the folder its user's."""
    declared = set(compose.get("volumes", {}))
    for service in services.values():
        user = service.dockerfile.instructions("USER")[-1]
        runs = " ".join(service.dockerfile.instructions("RUN"))
        owned = {
            folder
            for owner, folders in re.findall(r"chown (\S+) ([^;&|]+)", runs)
            if owner.split(":")[0] == user
            for folder in folders.split()
        }
        for volume, target in _named_volumes(service).items():
            assert volume in declared, f"{service.name}: volume {volume} is not declared"
            assert target in owned, (
                f"{service.name}: {target} is not made {user}'s in the image (STATE_DIRS)"
            )


def test_gateway_database_and_recordings_outlive_containers(services: dict[str, Service]) -> None:
    gateway = services["gateway"]
    data_dir = gateway.environment["WZ_GATEWAY_DATA_DIR"]
    assert "WZ_GATEWAY_DATABASE_URL" not in gateway.environment  # SQLite under data_dir
    assert data_dir in _named_volumes(gateway).values()
    recordings = {
        (service.name, target)
        for service in services.values()
        for volume, target in _named_volumes(service).items()
        if volume == "recordings"
    }
    assert recordings == {(ROUTER.name, "/var/lib/wz/recordings")}
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "record /var/lib/wz/recordings/" in readme


def test_gateway_is_published_on_the_host(services: dict[str, Service]) -> None:
    ports = [str(port) for port in services["gateway"].config["ports"]]
    assert ports == ["127.0.0.1:8000:8000"]  # the default of WZ_GATEWAY_PUBLISH
    published = interpolate(load_compose(), {**STAND_IN_ENV, "WZ_GATEWAY_PUBLISH": "0.0.0.0:80"})
    assert published["services"]["gateway"]["ports"] == ["0.0.0.0:80:8000"]


# --- environment --------------------------------------------------------------------------


def _settings_class(service: str) -> type[BaseSettings]:
    module, name = SETTINGS_CLASSES[service].split(":")
    found = getattr(importlib.import_module(module), name)
    assert inspect.isclass(found) and issubclass(found, BaseSettings)
    return found


def env_names(model: type[BaseModel], prefix: str) -> dict[str, Any]:
    """Environment names a settings class reads -> the field's annotation."""
    names: dict[str, Any] = {}
    for name, info in model.model_fields.items():
        alias = info.validation_alias
        env_name = alias if isinstance(alias, str) else prefix + name
        names[env_name.upper()] = info.annotation
    return names


def _nested_model(annotation: Any) -> type[BaseModel] | None:
    candidates = [annotation, *getattr(annotation, "__args__", ())]
    return next((c for c in candidates if inspect.isclass(c) and issubclass(c, BaseModel)), None)


def is_setting(variable: str, settings: type[BaseSettings]) -> bool:
    """Whether ``variable`` sets a field of ``settings`` (nested ``__`` fields included)."""
    prefix = str(settings.model_config.get("env_prefix", ""))
    names = env_names(settings, prefix)
    if variable in names:
        return True
    delimiter = settings.model_config.get("env_nested_delimiter")
    if not delimiter or delimiter not in variable:
        return False
    head, *rest = variable.split(delimiter)
    model = _nested_model(names.get(head))
    for part in rest:
        if model is None:
            return False
        fields = env_names(model, "")
        if part not in fields:
            return False
        model = _nested_model(fields[part])
    return True


#: Read with os.environ outside a settings class, by every process (wz_shared.logs).
READ_BY_LOGGING = {"WZ_LOG_FORMAT"}


def _use_environment(monkeypatch: pytest.MonkeyPatch, env: Mapping[str, str]) -> None:
    import os

    for name in list(os.environ):
        if name.startswith("WZ_"):
            monkeypatch.delenv(name)
    for name, value in env.items():
        monkeypatch.setenv(name, value)


def test_logging_variables_are_read_by_the_logging_setup() -> None:
    import wz_shared.logs

    source = inspect.getsource(wz_shared.logs)
    for variable in READ_BY_LOGGING:
        assert f'"{variable}"' in source


def test_settings_classes_have_the_stack_prefixes() -> None:
    for spec in STACK:
        assert _settings_class(spec.name).model_config.get("env_prefix") == spec.env_prefix


def test_every_variable_is_a_setting_of_its_service(
    services: dict[str, Service], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every WZ_* variable in compose or the image names a settings field of that service (or
    of the bus), and the values pass the settings' validation."""
    for service in services.values():
        settings = _settings_class(service.name)
        env = service.environment
        unknown = [
            name
            for name in env
            if name.startswith("WZ_")
            and name not in READ_BY_LOGGING
            and not is_setting(name, settings)
            and not is_setting(name, BusSettings)
        ]
        assert unknown == [], f"{service.name}: no such settings: {unknown}"
        with monkeypatch.context() as patched:
            _use_environment(patched, env)
            built = settings()
            BusSettings()
        if isinstance(built, ServiceSettings):
            assert str(built.site_file) == env["WZ_SITE_FILE"]
            assert (str(built.health_file) if built.health_file else None) == env.get(
                "WZ_HEALTH_FILE"
            )


def test_variable_check_catches_a_misspelling() -> None:
    from wz_lidar_detector.settings import LidarDetectorSettings

    assert is_setting("WZ_LIDAR_BACKGROUND_FILE", LidarDetectorSettings)
    assert not is_setting("WZ_LIDAR_BACKGROUND_PATH", LidarDetectorSettings)
    assert not is_setting("WZ_SIM_BACKGROUND_FILE", LidarDetectorSettings)
    assert is_setting("WZ_BUS_CONNECT_ENDPOINTS", BusSettings)
    assert not is_setting("WZ_BUS_CONNECT", BusSettings)


#: Where a container finds its bus credentials (the deployed zenoh configs' TLS paths).
TLS_MOUNT = "/etc/wz/tls"


def _credentials_source(service: Service) -> str:
    """The folder a service mounts at TLS_MOUNT, with the compose defaults put in."""
    (entry,) = [str(v) for v in service.config["volumes"] if f":{TLS_MOUNT}:" in str(v)]
    assert entry.endswith(f":{TLS_MOUNT}:ro"), f"{service.name}: credentials not read-only"
    interpolated = interpolate({"v": entry}, STAND_IN_ENV)["v"]
    return str(interpolated).rsplit(":", 2)[0]


def test_mounted_files_exist(services: dict[str, Service]) -> None:
    """What the repository ships exists; the credentials are the site's own (made with
    `wz credentials make`, never in git), checked in the next test."""
    for service in services.values():
        for entry in service.config.get("volumes", []):
            source = str(entry).split(":")[0]
            if source.startswith(".") and f":{TLS_MOUNT}:" not in str(entry):
                assert (COMPOSE_FILE.parent / source).exists(), f"{service.name}: {source}"


def test_each_container_mounts_its_own_credentials_that_wz_credentials_makes(
    services: dict[str, Service], tmp_path: Path
) -> None:
    """Every service, and the router, mounts its own identity's folder read-only at the path
    the deployed zenoh configs read, and only that one; `wz credentials make` writes each."""
    from wz_cli.credentials import make_site

    sources = {name: _credentials_source(service) for name, service in services.items()}
    site = "us75-lincoln"
    assert sources == {name: f"./credentials/{site}/{name}" for name in services}
    make_site(tmp_path, site)
    for name in services:
        folder = tmp_path / site / name
        # The router's also holds the site's access control (`wz router --tls-dir`).
        extra = ["access-control.json"] if name == "router" else []
        assert sorted(p.name for p in folder.iterdir()) == [*extra, "ca.pem", "cert.pem", "key.pem"]
    for path in (ROOT / "deploy" / "zenoh").glob("*.json5"):
        tls = json.loads(zenoh.Config.from_file(str(path)).get_json("transport/link/tls"))
        for value in tls.values():
            if isinstance(value, str) and value:
                assert value.startswith(f"{TLS_MOUNT}/"), f"{path.name}: {value}"
    assert _ignored("credentials/us75-lincoln/router/key.pem", _dockerignore())


def _ignored(path: str, patterns: list[str]) -> bool:
    """Whether .dockerignore leaves ``path`` out of the build context: the last pattern that
    matches it or one of its parent folders wins; ``!`` patterns put it back."""
    import fnmatch

    parents = [str(Path(*Path(path).parts[: n + 1])) for n in range(len(Path(path).parts))]
    ignored = False
    for pattern in patterns:
        keep = pattern.startswith("!")
        pattern = pattern.lstrip("!")
        anywhere = pattern.startswith("**/")  # matches a name at any depth
        pattern = pattern.removeprefix("**/")
        if any(fnmatch.fnmatch(Path(p).name if anywhere else p, pattern) for p in parents):
            ignored = not keep
    return ignored


def _dockerignore() -> list[str]:
    lines = (ROOT / ".dockerignore").read_text(encoding="utf-8").splitlines()
    return [line.strip() for line in lines if line.strip() and not line.startswith("#")]


def test_build_context_holds_what_the_images_copy_and_no_secrets(
    services: dict[str, Service],
) -> None:
    patterns = _dockerignore()
    for service in services.values():
        for stage in service.dockerfile.stages:
            for instruction, rest in stage:
                if instruction != "COPY" or rest.startswith("--from="):
                    continue
                for source in shlex.split(rest)[:-1]:
                    assert (ROOT / source).exists(), f"{service.name}: COPY {source}"
                    assert not _ignored(source, patterns), f"{service.name}: {source} ignored"
                    for inner in (ROOT / source).rglob("*.py") if (ROOT / source).is_dir() else ():
                        if "__pycache__" not in inner.parts:
                            relative = str(inner.relative_to(ROOT))
                            assert not _ignored(relative, patterns), relative
    for secret_or_bulk in (".env", ".venv/bin/python", ".git/config", "runs/eval", ".tools"):
        assert _ignored(secret_or_bulk, patterns), secret_or_bulk
    assert _ignored("shared/src/wz_shared/__pycache__/bus.cpython-311.pyc", patterns)


# --- the regional centre ------------------------------------------------------------------

REGIONAL_FILE = ROOT / "deploy" / "regional" / "docker-compose.yml"


def test_regional_file_is_valid_compose_and_serves_every_site() -> None:
    """The centre: the regional router and a central gateway given the sites folder, each
    with a probe, the gateway waiting for the router; what they mount exists."""
    raw = yaml.safe_load(REGIONAL_FILE.read_text(encoding="utf-8"))
    assert schema_errors(raw) == []
    assert schema_errors(interpolate(raw, STAND_IN_ENV)) == []
    router, gateway = raw["services"]["router"], raw["services"]["gateway"]
    mounts = {
        target: REGIONAL_FILE.parent / source
        for service in (router, gateway)
        for source, target, *_ in (str(v).split(":") for v in service["volumes"])
        if source.startswith(".")
    }
    config = router["command"][router["command"].index("--config") + 1]
    assert config == "/etc/wz/zenoh/regional-router.json5"
    assert (mounts["/etc/wz/zenoh"] / "regional-router.json5").is_file()
    assert _zenoh_endpoints(mounts["/etc/wz/zenoh"] / "regional-router.json5", "connect") == []
    env = gateway["environment"]
    assert env["WZ_GATEWAY_SITE_FILES"] == "/etc/wz/sites"
    assert list(mounts["/etc/wz/sites"].glob("*.yaml"))
    assert gateway["depends_on"]["router"]["condition"] == "service_healthy"
    for service in (router, gateway):
        assert service["healthcheck"]["test"][0] == "CMD" and service["restart"] in RESTART_POLICIES
    from wz_gateway.settings import GatewaySettings

    unknown = [
        name
        for name in env
        if name not in READ_BY_LOGGING
        and not is_setting(name, GatewaySettings)
        and not is_setting(name, BusSettings)
    ]
    assert unknown == []


def test_regional_images_are_the_edge_box_images(services: dict[str, Service]) -> None:
    """The centre's router and gateway are built as the edge box builds the images of the
    same tag (deploy/Dockerfile, the same args): one tag, one image, whichever file built it."""
    raw = interpolate(yaml.safe_load(REGIONAL_FILE.read_text(encoding="utf-8")), STAND_IN_ENV)
    for name, config in raw["services"].items():
        image = image_of(REGIONAL_FILE, name, config)
        edge = services[name]
        assert config["image"] == edge.config["image"], name
        assert image.build_args == edge.dockerfile.build_args, name
