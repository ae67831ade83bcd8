#!/usr/bin/env bash
# CURVE keys for the Kubernetes stack (deploy/README.md, "Kubernetes"):
#   deploy/k8s/make-keys.sh OUT [LFRECON]     # LFRECON: the CLI (default build/bin/lfrecon)
# writes OUT/ (mode 0700): one key pair per daemon and worker stage plus a client key
# (lfrecon keygen), and OUT/keys.yaml: a Secret per secret key (lfrecon-<name>-key)
# and the ConfigMap lfrecon-public (aggregate.pub and the two allow-lists), for
#   kubectl -n lfrecon apply -f OUT/keys.yaml
# Keep OUT/client.key for the client (lfrecon stream --key OUT/client.key --ingest-key
# OUT/ingest.pub --aggregate-key OUT/aggregate.pub). More clients: lfrecon keygen NAME
# --role client, append NAME.pub to both allow-lists, re-apply, restart both daemons.
set -euo pipefail
OUT="${1:?usage: make-keys.sh OUT [LFRECON]}"
ROOT="$(cd "$(dirname "$0")/../.." && pwd)"
LFRECON="${2:-$ROOT/build/bin/lfrecon}"
mkdir -p "$OUT"; chmod 700 "$OUT"
for nr in aggregate:server ingest:ingest depth:worker propagate:worker client:client; do
  n="${nr%%:*}"
  [ -f "$OUT/$n.key" ] || "$LFRECON" -q keygen "$n" --role "${nr#*:}" -o "$OUT" >/dev/null
done
cat "$OUT/ingest.pub" "$OUT/depth.pub" "$OUT/propagate.pub" "$OUT/client.pub" >"$OUT/aggregate.allow"
cat "$OUT/client.pub" >"$OUT/ingest.allow"
indent() { sed 's/^/    /'; }
{
  for n in aggregate ingest depth propagate; do
    cat <<YAML
apiVersion: v1
kind: Secret
metadata:
  name: lfrecon-$n-key
  namespace: lfrecon
  labels: {app.kubernetes.io/part-of: lfrecon}
type: Opaque
data:
  $n.key: $(base64 -w0 "$OUT/$n.key")
---
YAML
  done
  cat <<YAML
apiVersion: v1
kind: ConfigMap
metadata:
  name: lfrecon-public
  namespace: lfrecon
  labels: {app.kubernetes.io/part-of: lfrecon}
data:
  aggregate.pub: |
$(indent <"$OUT/aggregate.pub")
  aggregate.allow: |
$(indent <"$OUT/aggregate.allow")
  ingest.allow: |
$(indent <"$OUT/ingest.allow")
YAML
} >"$OUT/keys.yaml"
chmod 600 "$OUT/keys.yaml"
echo "make-keys: $OUT/keys.yaml (Secrets lfrecon-{aggregate,ingest,depth,propagate}-key, ConfigMap lfrecon-public); client key $OUT/client.key"
