# QuadLoc developer entry points. `make serve` and `make test` work on a fresh machine.
#
# Reproducible installs: the venv is installed from exact, hashed lock files; pyproject.toml keeps
# the version ranges for library users.
#   requirements-dev.lock  everything `make serve` / `make test` install (runtime + [dev] extra,
#                          pip and the build backend), every wheel's sha256 (pip --require-hashes)
#   requirements.lock      the runtime subset, same versions, minus IMAGE_DROP (the Docker image
#                          installs this one, with --no-deps)
#   make lock              re-resolve after editing pyproject.toml: keeps every pin that still
#                          fits, adds/removes what changed; `make lock UPGRADE=1` moves every pin
#                          to the newest allowed version. Local packages of the checkout (the
#                          project, and any sibling distribution it depends on by path) are
#                          never pinned: they are installed from the working tree, editable.
# Why pip-tools and not uv: pip-compile resolves with pip itself, so it honours the machine's pip
# configuration as is (this machine class reaches PyPI through a TLS-intercepting package proxy
# whose CA is in pip's `cert` setting; uv ships its own CA roots and indexes settings and needs
# extra configuration there), and installing needs nothing but the pip of python3 -m venv. Both
# lock files are plain `pip install -r` files. The locks are resolved for CPython 3.11 on Linux
# x86_64 (the machine class, and the image).
SHELL    := /bin/bash
PYTHON   ?= python3
VENV     ?= .venv
BIN      := $(VENV)/bin
STAMP    := $(VENV)/.installed
DEV_LOCK := requirements-dev.lock
RUN_LOCK := requirements.lock
# Directories of this checkout installed editable, without dependencies (those come from the
# lock): the server distribution and the light SDK distribution it depends on (sdk/python/).
LOCAL_PKGS := . sdk/python
# Test tools that gtsam 4.3.0 lists as run-time requirements (pytest, and what pytest pulls in)
# but never imports: left out of requirements.lock, so that the image carries no test tools.
IMAGE_DROP := pytest pluggy iniconfig pygments
LOCK_VENV  := .venv-lock
PIP_TOOLS  := pip-tools==7.5.3
LOCK_PIP   := pip==25.3
COMPILE    := CUSTOM_COMPILE_COMMAND="make lock" $(LOCK_VENV)/bin/pip-compile --quiet \
              --generate-hashes --allow-unsafe --strip-extras --no-emit-options \
              $(if $(UPGRADE),--upgrade)

.PHONY: serve test lint typecheck install bench clean lock sdk-models _install_locked

# `make serve` and `make test` may start together and share the venv: the install runs under an
# exclusive flock, and re-checks under the lock whether another make already did it.
$(STAMP): $(DEV_LOCK) pyproject.toml
	@flock $(VENV).lock $(MAKE) --no-print-directory _install_locked

_install_locked:
	@if [ -f $(STAMP) ] && [ $(STAMP) -nt $(DEV_LOCK) ] && [ $(STAMP) -nt pyproject.toml ]; then \
	    exit 0; fi; \
	set -e; \
	if ! $(BIN)/python -m pip --version >/dev/null 2>&1; then \
	    rm -rf $(VENV); $(PYTHON) -m venv $(VENV); fi; \
	rm -f $(STAMP); \
	$(BIN)/python -m pip install --require-hashes -r $(DEV_LOCK); \
	$(BIN)/python -m pip install --no-deps --no-build-isolation $(foreach p,$(LOCAL_PKGS),-e $(p)); \
	$(BIN)/python -m pip check || { echo "the lock files do not match pyproject.toml: run make lock" >&2; exit 1; }; \
	touch $(STAMP)

install: $(STAMP)

lint: $(STAMP)
	$(BIN)/ruff check .

# mypy (strict, pyproject.toml [tool.mypy]) on the installed namespace: mypy cannot follow the
# editable install's import hook (quadloc.factors -> factors/), so it reads the packages
# through a tree of links, build/typecheck/quadloc/<pkg> -> <pkg>/, and reports repository paths.
TYPED_PKGS := factors maps service
typecheck: $(STAMP)
	@rm -rf build/typecheck && mkdir -p build/typecheck/quadloc
	@for p in $(TYPED_PKGS); do ln -s ../../../$$p build/typecheck/quadloc/$$p; done
	@set -o pipefail; MYPYPATH=build/typecheck:sdk/python $(BIN)/mypy \
	    $(foreach p,$(TYPED_PKGS),-p quadloc.$(p)) -p quadloc_sdk \
	    | sed 's|^build/typecheck/quadloc/||'

# pytest also builds and tests the TypeScript and C# SDKs against live servers where node / mono
# are installed (tests/e2e/test_sdk_typescript.py, test_sdk_csharp.py; skipped with the reason
# elsewhere) and checks that their wire models match docs/openapi.json (tests/sdk).
test: $(STAMP)
	$(BIN)/ruff check .
	$(MAKE) --no-print-directory typecheck
	$(BIN)/python -m pytest

# The TypeScript and C# wire models regenerated from docs/openapi.json (after an API change and
# `quadloc openapi -o docs/openapi.json`); commit the two files it writes.
TS_SDK := sdk/typescript
sdk-models: $(STAMP)
	@[ $(TS_SDK)/node_modules/.package-lock.json -nt $(TS_SDK)/package-lock.json ] \
	    || (cd $(TS_SDK) && npm ci --no-audit --no-fund)
	cd $(TS_SDK) && npm run generate
	$(BIN)/python sdk/csharp/generate_models.py

serve: $(STAMP)
	$(BIN)/quadloc serve

# One command, re-runnable after any pyproject.toml change (see the header).
lock:
	@$(LOCK_VENV)/bin/python -m pip --version >/dev/null 2>&1 || $(PYTHON) -m venv $(LOCK_VENV)
	$(LOCK_VENV)/bin/python -m pip install --quiet "$(LOCK_PIP)" "$(PIP_TOOLS)"
	# the checkout's own distributions (., sdk/python/) are never resolved from an index: compile
	# their dependencies (lock/requirements_in.py)
	$(LOCK_VENV)/bin/python lock/requirements_in.py dev > $(LOCK_VENV)/dev.in
	$(LOCK_VENV)/bin/python lock/requirements_in.py > $(LOCK_VENV)/run.in
	$(COMPILE) -o $(DEV_LOCK) $(LOCK_VENV)/dev.in lock/tools.in
	cp $(DEV_LOCK) $(RUN_LOCK)  # same versions: the runtime resolution starts from the dev pins
	$(COMPILE) --no-upgrade -o $(RUN_LOCK) $(LOCK_VENV)/run.in lock/tools.in
	awk -v drop="$(IMAGE_DROP)" 'BEGIN { n = split(drop, a, " "); for (i = 1; i <= n; i++) d[a[i]] = 1 } \
	    /^[A-Za-z0-9]/ { name = $$0; sub(/[=<>@ ;].*/, "", name); skip = (name in d) } !skip' \
	    $(RUN_LOCK) > $(RUN_LOCK).tmp && mv $(RUN_LOCK).tmp $(RUN_LOCK)
	printf '#\n# Left out (make lock, IMAGE_DROP): $(IMAGE_DROP). gtsam declares pytest as a\n# run-time dependency but never imports it; the image installs this file with --no-deps.\n' >> $(RUN_LOCK)
	@echo "lock files written: $(DEV_LOCK) $(RUN_LOCK)"

clean:
	rm -rf $(VENV) $(VENV).lock $(LOCK_VENV) .pytest_cache .ruff_cache
