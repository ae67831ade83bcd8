#!/usr/bin/env python3
"""Offline checks of deploy/k8s/ (no cluster, no schema download).

usage: k8s_manifests_test.py DEPLOY_K8S_DIR BIN_DIR
Exit 0: every check passed; 1: a check failed (each printed); 77: skipped
(python3-yaml missing).
"""
import os
import re
import shutil
import subprocess
import sys
import tempfile

try:
    import yaml
except ImportError:
    print("SKIP: python3-yaml is not installed")
    sys.exit(77)

K8S, BIN = sys.argv[1], sys.argv[2]
errors = []


def check(cond, what):
    if not cond:
        errors.append(what)
    return cond


def load(path):
    with open(path) as f:
        return [d for d in yaml.safe_load_all(f) if d is not None]


docs = []
for name in sorted(os.listdir(K8S)):
    if name.endswith(".yaml") and name != "kustomization.yaml":
        try:
            loaded = load(os.path.join(K8S, name))
        except yaml.YAMLError as e:
            check(False, f"{name}: not YAML: {e}")
            continue
        for d in loaded:
            check(isinstance(d, dict) and "apiVersion" in d and "kind" in d and "name" in d.get("metadata", {}),
                  f"{name}: a document without apiVersion, kind or metadata.name")
            d["_file"] = name
            docs.append(d)
by = {(d["kind"], d["metadata"]["name"]): d for d in docs}

# Every file is a resource of the kustomization, and the kustomization names no missing file.
kust = load(os.path.join(K8S, "kustomization.yaml"))[0]
files = {n for n in os.listdir(K8S) if n.endswith(".yaml") and n != "kustomization.yaml"}
check(set(kust["resources"]) == files, f"kustomization resources {sorted(kust['resources'])} != files {sorted(files)}")
check(any(i.get("name") == "lfrecon" for i in kust.get("images", [])), "kustomization: no images entry for lfrecon")

# The kinds the service needs.
for kind, name in [("Namespace", "lfrecon"), ("PersistentVolumeClaim", "lfrecon-store"),
                   ("StatefulSet", "lfrecon-aggregate"), ("Service", "lfrecon-aggregate"),
                   ("Deployment", "lfrecon-ingest"), ("Service", "lfrecon-ingest"),
                   ("Deployment", "lfrecon-depth"), ("HorizontalPodAutoscaler", "lfrecon-depth"),
                   ("Deployment", "lfrecon-propagate"), ("HorizontalPodAutoscaler", "lfrecon-propagate")]:
    check((kind, name) in by, f"missing {kind} {name}")

pvc = by.get(("PersistentVolumeClaim", "lfrecon-store"), {})
check(pvc.get("spec", {}).get("accessModes") == ["ReadWriteMany"],
      "the job store claim must be ReadWriteMany (ingest, aggregator and workers mount it)")

for stage in ("depth", "propagate"):
    hpa = by.get(("HorizontalPodAutoscaler", f"lfrecon-{stage}"), {}).get("spec", {})
    check(hpa.get("scaleTargetRef", {}).get("kind") == "Deployment" and
          hpa.get("scaleTargetRef", {}).get("name") == f"lfrecon-{stage}", f"HPA lfrecon-{stage}: wrong target")
    check(1 <= hpa.get("minReplicas", 0) <= hpa.get("maxReplicas", 0), f"HPA lfrecon-{stage}: replica range")
    check(by.get(("Deployment", f"lfrecon-{stage}"), {}).get("spec", {}).get("replicas", 0) >= 1,
          f"Deployment lfrecon-{stage}: replicas")
sts = by.get(("StatefulSet", "lfrecon-aggregate"), {}).get("spec", {})
check(sts.get("replicas") == 1, "the aggregator StatefulSet must have 1 replica (one per store)")
check(("Service", sts.get("serviceName")) in by and by[("Service", sts.get("serviceName"))]["spec"].get(
    "clusterIP") == "None", "the StatefulSet's serviceName must be a headless Service")

# The keys make-keys.sh makes (with the built CLI), to match the Secrets and files the pods use.
secrets, public = {}, {}
lfrecon = os.path.join(BIN, "lfrecon")
if check(os.access(lfrecon, os.X_OK), f"{lfrecon} missing: build the lfrecon target"):
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "keys")
        r = subprocess.run([os.path.join(K8S, "make-keys.sh"), out, lfrecon], capture_output=True, text=True)
        if check(r.returncode == 0, f"make-keys.sh failed: {r.stdout}{r.stderr}"):
            st = os.stat(os.path.join(out, "keys.yaml")).st_mode
            check(st & 0o077 == 0, "make-keys.sh: keys.yaml readable by group or others")
            for d in load(os.path.join(out, "keys.yaml")):
                if d["kind"] == "Secret":
                    secrets[d["metadata"]["name"]] = set(d["data"])
                elif d["kind"] == "ConfigMap":
                    public[d["metadata"]["name"]] = d["data"]
            check("lfrecon-public" in public, "make-keys.sh: no ConfigMap lfrecon-public")
            for k in ("aggregate.pub", "aggregate.allow", "ingest.allow"):
                check(k in public.get("lfrecon-public", {}), f"make-keys.sh: lfrecon-public has no {k}")
            allow = public.get("lfrecon-public", {}).get("aggregate.allow", "")
            for role in ("ingest", "worker", "client"):
                check(re.search(rf"^{role} \S+ ", allow, re.M), f"aggregate.allow lists no {role} key")

helps = {}


def daemon_flags(exe):
    if exe not in helps:
        r = subprocess.run([exe, "--help"], capture_output=True, text=True)
        helps[exe] = set(re.findall(r"(--[a-z][a-z0-9-]*)", r.stdout + r.stderr))
    return helps[exe]


def mounted(path, mounts):
    return [m for m in mounts if path == m["mountPath"] or path.startswith(m["mountPath"].rstrip("/") + "/")]


services = {d["metadata"]["name"]: d for d in docs if d["kind"] == "Service"}
for d in docs:
    if d["kind"] not in ("Deployment", "StatefulSet"):
        continue
    where = f"{d['_file']}: {d['kind']} {d['metadata']['name']}"
    pod = d["spec"]["template"]["spec"]
    labels = d["spec"]["template"]["metadata"]["labels"]
    check(d["spec"]["selector"]["matchLabels"].items() <= labels.items(), f"{where}: selector does not match labels")
    psc = pod.get("securityContext", {})
    check(psc.get("runAsNonRoot") is True and psc.get("runAsUser", 0) > 0, f"{where}: runAsNonRoot / runAsUser")
    check(pod.get("automountServiceAccountToken") is False, f"{where}: automountServiceAccountToken not false")
    vols = {v["name"]: v for v in pod.get("volumes", [])}
    for c in pod.get("initContainers", []) + pod["containers"]:
        cw = f"{where} container {c['name']}"
        check(bool(c.get("image")), f"{cw}: no image")
        res = c.get("resources", {})
        for kind in ("requests", "limits"):
            for r in ("cpu", "memory"):
                check(r in res.get(kind, {}), f"{cw}: no {kind}.{r}")
        sc = c.get("securityContext", {})
        check(sc.get("allowPrivilegeEscalation") is False, f"{cw}: allowPrivilegeEscalation not false")
        check(sc.get("readOnlyRootFilesystem") is True, f"{cw}: readOnlyRootFilesystem not true")
        check("ALL" in sc.get("capabilities", {}).get("drop", []), f"{cw}: capabilities not dropped")
        check(not sc.get("privileged", False), f"{cw}: privileged")
        mounts = c.get("volumeMounts", [])
        for m in mounts:
            v = vols.get(m["name"])
            if not check(v is not None, f"{cw}: mount of unknown volume {m['name']}"):
                continue
            if "secret" in v:
                check(m.get("readOnly") is True, f"{cw}: Secret {v['secret']['secretName']} not mounted read-only")
                check(v["secret"].get("defaultMode", 0o644) & 0o007 == 0,
                      f"{cw}: Secret {v['secret']['secretName']} readable by others")
                check(c in pod.get("initContainers", []),
                      f"{cw}: the daemon reads a Secret volume directly (lfrecon refuses group-readable keys)")
                if secrets:
                    check(v["secret"]["secretName"] in secrets, f"{cw}: make-keys.sh makes no Secret "
                          f"{v['secret']['secretName']}")
            if "configMap" in v and public:
                check(v["configMap"]["name"] in public, f"{cw}: make-keys.sh makes no ConfigMap {v['configMap']['name']}")
        # Every file a command names lies in a mounted volume, and is a key the volume has.
        args = c.get("command", []) + c.get("args", [])
        for a in args:
            path = a.split("=", 1)[1] if a.startswith("--") and "=" in a else a
            if not path.startswith(("/secret", "/run/", "/etc/lfrecon", "/var/lib/lfrecon", "/srv/")):
                continue
            ms = mounted(path, mounts)
            if not check(ms, f"{cw}: {path} is in no mounted volume"):
                continue
            v = vols[ms[0]["name"]]
            rel = os.path.relpath(path, ms[0]["mountPath"])
            if "secret" in v and secrets:
                check(rel in secrets.get(v["secret"]["secretName"], set()),
                      f"{cw}: Secret {v['secret']['secretName']} has no {rel}")
            if "configMap" in v and public:
                check(rel in public.get(v["configMap"]["name"], {}), f"{cw}: ConfigMap has no {rel}")
        if c in pod.get("initContainers", []):
            continue
        # The daemon: its flags exist, the store is the shared claim, keys come from the init copy.
        exe = c["command"][0]
        check(re.fullmatch(r"/usr/local/bin/lfrecon-(aggregate|ingest|depth|propagate)", exe), f"{cw}: command {exe}")
        local = os.path.join(BIN, os.path.basename(exe))
        if check(os.access(local, os.X_OK), f"{local} missing: build it"):
            for a in c.get("args", []):
                if a.startswith("--"):
                    check(a.split("=")[0] in daemon_flags(local), f"{cw}: {os.path.basename(exe)} has no flag {a}")
        flags = dict(a[2:].split("=", 1) for a in c.get("args", []) if a.startswith("--") and "=" in a)
        store = mounted(flags.get("store", "?"), mounts)
        if check(store and "persistentVolumeClaim" in vols[store[0]["name"]], f"{cw}: --store not on a claim"):
            check(vols[store[0]["name"]]["persistentVolumeClaim"]["claimName"] == "lfrecon-store",
                  f"{cw}: --store is not the shared lfrecon-store claim")
            worker = exe.endswith(("-depth", "-propagate"))
            check(bool(store[0].get("readOnly")) == worker, f"{cw}: the store must be read-only for workers only")
        check("key" in flags, f"{cw}: no --key (CURVE)")
        check("insecure" not in " ".join(c.get("args", [])), f"{cw}: --insecure")
        if "bind" in flags:
            port = int(flags["bind"].rsplit(":", 1)[1])
            ports = {p["containerPort"]: p.get("name") for p in c.get("ports", [])}
            check(port in ports, f"{cw}: binds {port}, no containerPort {port}")
            for probe in ("readinessProbe", "livenessProbe"):
                check(c.get(probe, {}).get("tcpSocket", {}).get("port") in (port, ports.get(port)),
                      f"{cw}: no {probe} on its port")
            svc = services.get(d["metadata"]["name"])
            if check(svc is not None, f"{cw}: no Service {d['metadata']['name']}"):
                check(svc["spec"]["selector"].items() <= labels.items(), f"{cw}: Service selector misses the pod")
                check(any(p.get("targetPort") in (port, ports.get(port)) for p in svc["spec"]["ports"]),
                      f"{cw}: Service does not target port {port}")
        if "aggregate" in flags:
            m = re.fullmatch(r"tcp://([a-z0-9-]+):(\d+)", flags["aggregate"])
            if check(m, f"{cw}: --aggregate {flags['aggregate']}"):
                svc = services.get(m.group(1))
                check(svc is not None and any(p["port"] == int(m.group(2)) for p in svc["spec"]["ports"]),
                      f"{cw}: --aggregate {flags['aggregate']} is no Service port")

kubectl = shutil.which("kubectl")
if kubectl:
    env = dict(os.environ, KUBECONFIG=os.devnull)
    r = subprocess.run([kubectl, "kustomize", K8S], capture_output=True, text=True, env=env)
    if check(r.returncode == 0, f"kubectl kustomize failed: {r.stderr}"):
        rendered = [d for d in yaml.safe_load_all(r.stdout) if d]
        check(len(rendered) == len(docs), f"kubectl kustomize: {len(rendered)} resources, files have {len(docs)}")
        check(all(d["metadata"].get("namespace") == "lfrecon" for d in rendered if d["kind"] != "Namespace"),
              "kubectl kustomize: a resource outside the lfrecon namespace")
else:
    print("note: kubectl not installed, kustomize rendering not checked")

for e in errors:
    print("FAIL:", e)
print(f"{len(docs)} resources in {K8S}: {len(errors)} problem(s)")
sys.exit(1 if errors else 0)
