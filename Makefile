# darkread — one Makefile for set-up, tests, benchmarks and the demo.
# Everything runs from a local virtual environment (.venv) that the targets create on demand.

PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
EXTRAS ?= edge,cloud,dev,train,gaze,hesim
# What `make demo` runs: the edge and the cloud on one machine. The lab, training and test extras
# (PyTorch, hesim, eyekit, the test oracles) come with `make venv` / `make test` and their targets.
DEMO_EXTRAS := edge,cloud
# One stamp per extras set: the full set also satisfies the demo's.
STAMP      := $(VENV)/.installed
DEMO_STAMP := $(VENV)/.installed-demo
HESIM  := hesim-3d==0.1.0
PYTEST_ARGS ?=  # e.g. make test PYTEST_ARGS="-m postgres"

.PHONY: help venv venv-demo hesim test lint typecheck test-fast bench demo eval eval-small eval-hesim eval-photoreceptor eval-grounded train clean system-deps speech-deps browser-deps ocr-deps postgres-deps

help:  ## list the targets
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | sed 's/:.*## /\t/' | column -t -s "$$(printf '\t')"

# install-darkread EXTRAS: the virtual environment, then darkread (editable) with those extras;
# one progress line per step (pip itself stays quiet)
define install-darkread
	@test -x $(PY) || { echo "set-up: creating the virtual environment $(VENV)"; $(PYTHON) -m venv $(VENV); }
	@echo "set-up: pip, setuptools and wheel in $(VENV)"
	@$(PIP) install -q --upgrade pip "setuptools>=77" wheel
	@echo "set-up: darkread and its [$(1)] dependencies (the first time takes minutes)"
	@$(PIP) install -q -e ".[$(1)]"
endef

$(DEMO_STAMP): pyproject.toml setup.py
	$(call install-darkread,$(DEMO_EXTRAS))
	@$(PY) -c "import cv2; cv2.aruco"
	@touch $(DEMO_STAMP)

$(STAMP): pyproject.toml setup.py
	$(call install-darkread,$(EXTRAS))
	@# test oracle for the Aria gaze conventions; its own dependencies (1.6 GB) are not needed
	@echo "set-up: projectaria-tools (the gaze test oracle, without its dependencies)"
	@$(PIP) install -q --no-deps "projectaria-tools==2.3.0"
	@# the second event simulator, without the opencv-python it declares (it would break our cv2); its
	@# run-time needs are the `hesim` extra
	@$(if $(findstring hesim,$(EXTRAS)),echo "set-up: $(HESIM) (without its opencv-python)" && $(PIP) install -q --no-deps "$(HESIM)")
	@$(PY) -c "import cv2; cv2.aruco"
	@touch $(STAMP) $(if $(and $(findstring edge,$(EXTRAS)),$(findstring cloud,$(EXTRAS))),$(DEMO_STAMP))

venv: $(STAMP)  ## create .venv and install darkread with all extras

venv-demo: $(DEMO_STAMP)  ## create .venv with only what the demo runs (edge and cloud)

hesim: $(STAMP)  ## the second event simulator (hesim-3d, installed by venv without opencv-python): check it imports beside our cv2
	$(PY) -c "import cv2, hesim3d; cv2.aruco; print('hesim-3d', hesim3d.__version__, 'beside cv2', cv2.__version__)"

# Debian packages, installed only when run as root with apt-get (a fresh machine, CI, the image);
# elsewhere the tests that need them skip with the reason. Each target installs only what is missing.
APT_INSTALL = apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends

system-deps: speech-deps browser-deps ocr-deps  ## every Debian package the tests use (when root)

speech-deps:  ## espeak-ng, the offline speech engine of spoken answers (when root)
	@if command -v espeak-ng >/dev/null; then :; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null; then echo "set-up: apt-get install espeak-ng"; $(APT_INSTALL) espeak-ng >/dev/null; \
	else echo "speech-deps: not root or no apt-get; install espeak-ng for spoken answers"; fi

browser-deps:  ## Chromium and its WebDriver for the live-page browser test (when root)
	@if command -v chromium >/dev/null && command -v chromedriver >/dev/null; then :; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null; then echo "set-up: apt-get install chromium chromium-driver"; $(APT_INSTALL) chromium chromium-driver >/dev/null; \
	else echo "browser-deps: not root or no apt-get; the browser test will skip"; fi

ocr-deps:  ## Tesseract (an optional second local OCR engine) and libcairo2 for eyekit (when root)
	@if [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null; then \
		command -v tesseract >/dev/null || (echo "set-up: apt-get install tesseract-ocr" && $(APT_INSTALL) tesseract-ocr tesseract-ocr-eng >/dev/null) || true; \
		ldconfig -p | grep -q libcairo.so.2 || (echo "set-up: apt-get install libcairo2" && $(APT_INSTALL) libcairo2 >/dev/null) || true; \
	else echo "ocr-deps: not root or no apt-get; Tesseract stays optional"; fi

postgres-deps:  ## Debian's PostgreSQL server (initdb, pg_ctl) for the tests and benchmarks, when run as root
	@if ls /usr/lib/postgresql/*/bin/pg_ctl >/dev/null 2>&1 || command -v pg_ctl >/dev/null; then :; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null; then \
		echo "set-up: apt-get install postgresql"; \
		(apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends postgresql >/dev/null) \
			|| echo "postgres-deps: apt-get install postgresql failed; the postgres tests will say so"; \
	else echo "postgres-deps: no PostgreSQL server binaries and not root: install postgresql (the postgres tests skip, or fail under CI)"; fi

test: system-deps postgres-deps $(STAMP) lint typecheck  ## lint, type-check and run the whole test suite (installs espeak-ng, Chromium, Tesseract, libcairo2, PostgreSQL when root)
	$(PY) -m pytest -q $(PYTEST_ARGS)

lint: $(STAMP)  ## ruff: lint and import order ([tool.ruff] in pyproject.toml)
	$(VENV)/bin/ruff check .

# mypy reads the installed layout (the top-level folders inside darkread/) from a tree of links
TYPECHECK_DIR := build/typecheck
typecheck: $(STAMP)  ## mypy over darkread as installed ([tool.mypy] in pyproject.toml)
	rm -rf $(TYPECHECK_DIR)/darkread && mkdir -p $(TYPECHECK_DIR)/darkread
	for entry in darkread/*; do ln -s ../../../$$entry $(TYPECHECK_DIR)/darkread/; done
	for top in edge cloud proto stitch models lab; do ln -s ../../../$$top $(TYPECHECK_DIR)/darkread/$$top; done
	cd $(TYPECHECK_DIR) && ../../$(VENV)/bin/mypy --config-file ../../pyproject.toml -p darkread

test-fast: $(STAMP) postgres-deps  ## unit tests only (no integration tests)
	$(PY) -m pytest -q -m "not slow"

bench: $(STAMP) postgres-deps  ## benchmarks; prints a table and writes bench.json
	$(VENV)/bin/darkread bench

demo: $(DEMO_STAMP) speech-deps  ## read the shipped sample recording aloud and compare with its printed text (installs only edge and cloud)
	@echo "demo: darkread read --demo --say"
	@$(VENV)/bin/darkread read --demo --say

# the suite read again by an edge held at the shedding levels that cost reading (edge.load: one frame per view, and no
# view where the last one covers the window), as a live edge starved of CPU makes them: lines the confidence model
# learns a starved page from (docs/edge_cpu.md)
SHED_RUNS = for l in 2 3; do $(VENV)/bin/darkread eval run runs/eval_suite --work runs/shed/level$$l --out runs/shed/report$$l \
	--edge-shed-level $$l --no-rgb --compare --jobs 2 || exit 1; done
SHED_ALSO := --also runs/shed/level2 --also runs/shed/level3
eval: $(STAMP)  ## the full suite (93 recordings) in both edge modes (~30 min on 2 cores, half of it making the suite): report in docs/eval, the default mode first, with how much ink the events show; then the line-confidence model fitted (cloud/data/line_confidence.json, docs/eval/calibration.md) and the report rebuilt with coverage and risk under it
	$(VENV)/bin/darkread eval make-suite runs/eval_suite --jobs 2
	$(VENV)/bin/darkread eval evidence runs/eval_suite --out docs/eval --jobs 2
	$(VENV)/bin/darkread eval run runs/eval_suite --out docs/eval --infer both --jobs 2
	$(SHED_RUNS)
	# the line-confidence model the cloud ships, fitted on half the recordings' lines and measured on the other half
	$(VENV)/bin/darkread eval calibrate runs/eval_suite --out docs/eval $(SHED_ALSO)
	$(VENV)/bin/darkread eval run runs/eval_suite --out docs/eval --infer both --report-only --before docs/eval/before/results.json

eval-small: $(STAMP)  ## the small suite (17 recordings) in both edge modes (a few minutes); report in runs/eval_small_report
	$(VENV)/bin/darkread eval make-suite runs/eval_small --small --jobs 2
	$(VENV)/bin/darkread eval run runs/eval_small --out runs/eval_small_report --infer both --jobs 2

eval-hesim: hesim  ## the second-simulator check: 18 recordings of the suite made by each simulator (30/10/5 lux), read end to end; CER per lux side by side in docs/eval/simulators.md, the "Second simulator" section of the next `make eval` report (~1 h on 2 cores)
	nice -n 10 $(VENV)/bin/darkread eval make-suite runs/eval_hesim/darkread --subset simulator-check --jobs 2
	nice -n 10 $(VENV)/bin/darkread eval make-suite runs/eval_hesim/hesim --subset simulator-check --simulator hesim --jobs 2
	$(VENV)/bin/darkread eval run runs/eval_hesim/darkread --out runs/eval_hesim/report_darkread --jobs 2
	$(VENV)/bin/darkread eval run runs/eval_hesim/hesim --out runs/eval_hesim/report_hesim --no-rgb --compare --jobs 2
	$(VENV)/bin/darkread eval compare-simulators runs/eval_hesim/darkread runs/eval_hesim/hesim --out docs/eval/simulators.md

eval-photoreceptor: $(STAMP)  ## what the photoreceptor's speed in the dark decides: the suite's 27 recordings at 10 and 5 lux made again with --regime fast-photoreceptor, read in both edge modes (~10 min on 2 cores); report and evidence in runs/eval_photoreceptor_report (models/MODEL_CARD.md)
	$(VENV)/bin/darkread eval make-suite runs/eval_photoreceptor --regime fast-photoreceptor --match '*_lux10_*' --match '*_lux5_*' --jobs 2
	$(VENV)/bin/darkread eval evidence runs/eval_photoreceptor --out runs/eval_photoreceptor_report --jobs 2
	$(VENV)/bin/darkread eval run runs/eval_photoreceptor --out runs/eval_photoreceptor_report --infer both --no-rgb --jobs 2

# the grounded suite (issue 48): the suite's grid made again on the sensor model and head motion of published
# measurements, the same scenes; dark-profile, K-band, head-motion-band and one-law-at-a-time variants at 10 and 5 lux
G_SUITE := runs/grounded
G_MAKE  := $(VENV)/bin/darkread eval make-suite --jobs 2
G_RUN   := $(VENV)/bin/darkread eval run --compare --jobs 2
G_GRID  := --regime grounded --motion-regime grounded
G_DARK  := --match '*_lux10_*' --match '*_lux5_*' --limit 24
G_FIVE  := --match '*_lux5_*' --limit 12
# the grounded suites whose lines the line-confidence model is fitted on beside the suite's (central_factory_30
# holds the same 30-lux scenes as central_factory: left out so that no scene counts twice; slow_factory,
# fast_dark, fast_factory and central_dark_strong are kept out as a check on suites it never saw, docs/eval/grounded.md)
G_CALIBRATE := central_factory central_dark standard slow_dark central_dark_quiet law_motion law_noise \
	law_photoreceptor law_dark-current law_photoreceptor_dark-current
G_STD   := --match '*_lux30_*' --match '*_lux10_*' --match '*_lux5_*' --limit 36
eval-grounded: $(STAMP)  ## the suite re-made on the grounded sensor model and head motion (~2.5 h on 2 cores): factory and dark biases, K's band and the head motion's at their ends, one law at a time; docs/eval/grounded*.md
	$(G_MAKE) $(G_SUITE)/central_factory $(G_GRID) --k central --limit 60
	$(G_RUN) $(G_SUITE)/central_factory --out $(G_SUITE)/report_central_factory
	$(G_MAKE) $(G_SUITE)/central_factory_30 $(G_GRID) --k central --match '*_lux30_*' --limit 21
	$(G_RUN) $(G_SUITE)/central_factory_30 --out $(G_SUITE)/report_central_factory_30
	$(G_MAKE) $(G_SUITE)/standard $(G_STD)
	$(VENV)/bin/darkread eval add-imu $(G_SUITE)/standard
	$(G_RUN) $(G_SUITE)/standard --out $(G_SUITE)/report_standard --no-rgb
	for v in "central_dark --k central --biases dark" "slow_dark --k slow --biases dark" "slow_factory --k slow" \
	         "fast_dark --k fast --biases dark" "fast_factory --k fast"; do \
		set -- $$v; name=$$1; shift; \
		$(G_MAKE) $(G_SUITE)/$$name $(G_GRID) $$* $(G_DARK) && $(G_RUN) $(G_SUITE)/$$name --out $(G_SUITE)/report_$$name --no-rgb || exit 1; \
	done
	for m in quiet strong; do \
		$(G_MAKE) $(G_SUITE)/central_dark_$$m --regime grounded --motion-regime $$m --k central --biases dark $(G_DARK) && \
		$(G_RUN) $(G_SUITE)/central_dark_$$m --out $(G_SUITE)/report_central_dark_$$m --no-rgb || exit 1; \
	done
	$(G_MAKE) $(G_SUITE)/law_motion --regime grounded --motion-regime standard --k central $(G_FIVE)
	$(G_RUN) $(G_SUITE)/law_motion --out $(G_SUITE)/report_law_motion --no-rgb
	for law in photoreceptor noise dark-current; do \
		$(G_MAKE) $(G_SUITE)/law_$$law $(G_GRID) --k central --standard-law $$law $(G_FIVE) && \
		$(G_RUN) $(G_SUITE)/law_$$law --out $(G_SUITE)/report_law_$$law --no-rgb || exit 1; \
	done
	$(G_MAKE) $(G_SUITE)/law_photoreceptor_dark-current $(G_GRID) --k central --standard-law photoreceptor \
		--standard-law dark-current $(G_FIVE)
	$(G_RUN) $(G_SUITE)/law_photoreceptor_dark-current --out $(G_SUITE)/report_law_pd --no-rgb
	$(MAKE) --no-print-directory grounded-pages G_SUITE=$(G_SUITE)
	# the line-confidence model the cloud ships, fitted on the suite's lines and the grounded suites' (make eval first)
	$(SHED_RUNS)
	$(VENV)/bin/darkread eval calibrate runs/eval_suite --out docs/eval $(foreach s,$(G_CALIBRATE),--also $(G_SUITE)/$(s)) $(SHED_ALSO)
	$(VENV)/bin/darkread eval run runs/eval_suite --out docs/eval --infer on-change --report-only --before docs/eval/before/results.json

grounded-pages: $(STAMP)  ## the pages of docs/eval/grounded/ from the evaluated grounded suites (runs/grounded)
	$(VENV)/bin/darkread eval side-by-side "grounded=$(G_SUITE)/central_factory" "standard (old)=$(G_SUITE)/standard" \
		--reference "standard (old)" --out docs/eval/grounded/model.md --title "The grounded model against the old standard one"
	$(VENV)/bin/darkread eval side-by-side "grounded=$(G_SUITE)/central_factory_30" "today=runs/eval_suite" --reference today \
		--out docs/eval/grounded/thirty_lux.md --title "Every 30-lux recording of the suite, grounded against today's (make eval)"
	$(VENV)/bin/darkread eval side-by-side "factory, K 130=$(G_SUITE)/central_factory" "dark, K 130=$(G_SUITE)/central_dark" \
		"factory, K 40=$(G_SUITE)/slow_factory" "dark, K 40=$(G_SUITE)/slow_dark" "factory, K 400=$(G_SUITE)/fast_factory" \
		"dark, K 400=$(G_SUITE)/fast_dark" --out docs/eval/grounded/dark_profile.md \
		--title "The dark bias profile across the photoreceptor's band"
	$(VENV)/bin/darkread eval side-by-side "quiet head=$(G_SUITE)/central_dark_quiet" "grounded head=$(G_SUITE)/central_dark" \
		"strong head=$(G_SUITE)/central_dark_strong" --reference "grounded head" --out docs/eval/grounded/head_motion.md \
		--title "The head motion's band (dark profile, K 130)"
	$(VENV)/bin/darkread eval side-by-side "grounded=$(G_SUITE)/central_factory" "photoreceptor=$(G_SUITE)/law_photoreceptor" \
		"noise=$(G_SUITE)/law_noise" "dark current=$(G_SUITE)/law_dark-current" \
		"photoreceptor and dark current=$(G_SUITE)/law_photoreceptor_dark-current" "head motion=$(G_SUITE)/law_motion" \
		"standard (old)=$(G_SUITE)/standard" --reference grounded --out docs/eval/grounded/attribution.md \
		--title "One law at a time: the grounded model with each law put back to the standard one's (5 lux)"

train: $(STAMP)  ## reproduce the shipped model from scratch
	$(VENV)/bin/darkread train all

clean:  ## remove build artefacts (keeps .venv)
	rm -rf build dist *.egg-info .pytest_cache bench.json
