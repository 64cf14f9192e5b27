# rendiff: the front door for developers and CI. `.ci/run` runs `make test`.
CARGO ?= cargo
export CARGO_TERM_COLOR ?= never

.PHONY: test lint unit golden golden-check bless bench bench-report scaling peers fuzz doc clean

## The whole test suite: formatting, lints, unit, integration and doc
## tests, then (where POV-Ray is installed) the check that every stored
## POV-Ray reference is current and still what POV-Ray renders.
test: lint unit doc golden-check

lint:
	$(CARGO) fmt --all --check
	$(CARGO) fmt --manifest-path peers/Cargo.toml --check
	$(CARGO) fmt --manifest-path fuzz/Cargo.toml --check
	$(CARGO) fmt --manifest-path examples/user-crate/Cargo.toml --check
	$(CARGO) clippy --workspace --all-targets -- -D warnings

unit:
	$(CARGO) test --workspace

## Re-render the POV-Ray references of the bundled scenes (golden/pov)
## and of the hazard scenes (tests/data/hazards/golden).
HAZARDS = tests/data/hazards/*.toml --golden tests/data/hazards/golden
golden:
	$(CARGO) run --release -- golden --update
	$(CARGO) run --release -- golden --update $(HAZARDS)

## Check mode: re-render into a temporary folder and compare bit for bit.
## Skipped without POV-Ray unless RENDIFF_REQUIRE_POVRAY=1 (as in CI).
## It runs the binary the test build makes (`cargo test --no-run`, a no-op
## after `make unit`): `cargo run` would build the library and binary a
## second time without the dev-dependencies' features (~60 s on 2 cores).
TEST_BIN = "$${CARGO_TARGET_DIR:-target}/debug/rendiff"
golden-check:
	@if command -v povray >/dev/null 2>&1; then \
		$(CARGO) test -q --workspace --no-run && \
		$(TEST_BIN) golden && $(TEST_BIN) golden $(HAZARDS); \
	elif [ "$${RENDIFF_REQUIRE_POVRAY:-0}" = 1 ]; then \
		echo "golden-check: povray is required but not installed" >&2; exit 1; \
	else \
		echo "golden-check: skipped (povray is not installed; sudo apt-get install -y povray)"; \
	fi

## Rewrite the regression goldens that fail (golden/raster, golden/ray) and
## accept changed insta snapshots; review the diff before committing.
bless:
	UPDATE_GOLDEN=1 $(CARGO) test --test it golden
	INSTA_UPDATE=always $(CARGO) test --test it

## Coverage-guided fuzzing (cargo fuzz, nightly): every target for
## FUZZ_SECONDS, then its corpus minimised. Debug assertions on (an
## overflow is a crash); no sanitizer (the crate has no unsafe code, and
## AddressSanitizer made replaying the scene corpus 3.3× slower). New inputs land in
## fuzz/corpus/TARGET, crashes in fuzz/artifacts/TARGET; commit both (the
## corpora replay in `make test`, and a crash stays as a regression case).
FUZZ_SECONDS ?= 60
FUZZ_TARGETS = scene_text scene_files obj_bytes png_bytes polygon triangles
fuzz:
	@mkdir -p target/fuzz-logs; for t in $(FUZZ_TARGETS); do \
		echo "== $$t"; \
		$(CARGO) +nightly fuzz run -O -a -s none $$t -- -max_total_time=$(FUZZ_SECONDS) -print_final_stats=1 \
			> target/fuzz-logs/$$t.log 2>&1; status=$$?; \
		grep -E 'stat::number_of_executed_units|stat::new_units_added' target/fuzz-logs/$$t.log; \
		if [ $$status -ne 0 ]; then \
			echo "fuzz: $$t failed; see target/fuzz-logs/$$t.log and fuzz/artifacts/$$t" >&2; exit 1; \
		fi; \
		$(CARGO) +nightly fuzz cmin -O -a -s none $$t > target/fuzz-logs/$$t.cmin.log 2>&1 || { \
			echo "fuzz: minimising $$t failed; see target/fuzz-logs/$$t.cmin.log" >&2; exit 1; }; \
	done

## Benchmarks (release profile).
bench:
	$(CARGO) bench

## Run time against error on every bundled scene: results.csv, one
## time-against-error plot per scene and plan_savings.svg.
bench-report:
	$(CARGO) run --release -- bench --out target/rendiff-bench

## Time against triangle count and resolution, with the fitted growth.
scaling:
	$(CARGO) run --release -- bench --scaling --out target/rendiff-scaling

## rendiff beside Embree 3 (rays, builds), POV-Ray 3.7 (render phase and
## whole process) and Mesa llvmpipe (the rasterizer's shaded frame), one
## thread, ending in the table of every measure; needs `apt-get install
## libembree-dev povray libegl-dev libgl1-mesa-dev libgl1-mesa-dri`.
## Not part of `make test`. (`rendiff-peers embree|povray|llvmpipe` run
## one comparison, on 1 and on all threads.)
peers:
	$(CARGO) clippy --release --manifest-path peers/Cargo.toml -- -D warnings
	$(CARGO) build --release
	$(CARGO) run --release --manifest-path peers/Cargo.toml -- summary

doc:
	RUSTDOCFLAGS="-D warnings" $(CARGO) doc --workspace --no-deps

clean:
	$(CARGO) clean
