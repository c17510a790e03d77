#!/bin/bash
# Makes a lab's certificates for Zenoh's TLS, into DIR (default ./certs): a certificate
# authority (ca.pem, ca.key: keep the key off the lab's machines once done), the bridge's
# certificate for the names and addresses agents reach it at, and one agent certificate
# (with mutual TLS, only sessions holding a certificate of this authority get in).
#
#   docs/zenoh/make-certs.sh certs lab-pc 192.168.1.20
#
# localhost and 127.0.0.1 are always included. Every key is P-256, every certificate is good
# for a year.
set -euo pipefail
dir=${1:-certs}
shift || true
san="DNS:localhost,IP:127.0.0.1"
for name in "$@"; do
  if [[ $name =~ ^[0-9.]+$ || $name == *:* ]]; then san+=",IP:$name"; else san+=",DNS:$name"; fi
done
mkdir -p "$dir"
cd "$dir"
key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }
key ca.key
openssl req -x509 -new -key ca.key -out ca.pem -days 365 -subj "/CN=iwsim lab CA" \
  -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign"
sign() { # NAME CN EXTENSIONS
  key "$1.key"
  openssl req -new -key "$1.key" -out "$1.csr" -subj "/CN=$2"
  openssl x509 -req -in "$1.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -out "$1.pem" -days 365 \
    -extfile <(printf '%s\n' "$3") 2>/dev/null
  rm "$1.csr"
}
sign bridge "iwsim bridge" "subjectAltName=$san
extendedKeyUsage=serverAuth,clientAuth
basicConstraints=critical,CA:FALSE"
sign agent "iwsim agent" "extendedKeyUsage=clientAuth
basicConstraints=critical,CA:FALSE"
chmod 600 ./*.key
echo "certificates in $(pwd): ca.pem, bridge.pem/.key, agent.pem/.key"
