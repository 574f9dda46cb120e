# The product's front door: `make run` and `make test` set everything up themselves.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run inspect test install chromium clean bench demo paper

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

# The station's main job on simulated hardware: one inspection of the standard part
# (twins on 127.0.0.1, real drivers, vision, compensation, results in var/station.db).
run: $(STAMP)
	$(BIN)/station inspect --part ZDZG-22.2-12.3851 --serial SN-$$(date +%Y%m%d-%H%M%S)

# Commissioning: an ISO 230-2 run of Z, compensation table, discovery (out/demo/).
demo: $(STAMP)
	$(BIN)/station demo --out out/demo

# The seed paper's experiment (Table 4) on a twin of its station.
paper: $(STAMP)
	$(BIN)/station paper

# The browser tests drive Debian's Chromium (Playwright's own download is not used).
# Missing, it is installed here; when that fails the browser tests fail (never skip).
CHROMIUM := /usr/bin/chromium
chromium:
	@if [ ! -x $(CHROMIUM) ]; then \
	  echo "installing Debian's chromium for the browser tests (tests/browser)"; \
	  SUDO=; [ "$$(id -u)" = 0 ] || SUDO="sudo -n"; \
	  { $$SUDO apt-get update -q && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q chromium; } \
	    || echo "WARNING: could not install chromium: the browser tests will fail"; \
	fi

test: $(STAMP) chromium
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	$(BIN)/station bench kinematics
	$(BIN)/station bench inspect

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
