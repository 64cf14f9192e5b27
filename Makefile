# rendiff: the front door for developers and CI. `.ci/run` runs `make test`.
CARGO ?= cargo
export CARGO_TERM_COLOR ?= never

.PHONY: test lint unit golden golden-check bless bench fuzz doc clean

## The whole test suite: formatting, lints, unit, integration and doc tests.
test: lint unit

lint:
	$(CARGO) fmt --all --check
	$(CARGO) clippy --all-targets -- -D warnings

unit:
	$(CARGO) test

## Rewrite the regression goldens that fail (golden/raster, golden/ray) and
## accept changed insta snapshots; review the diff before committing.
bless:
	UPDATE_GOLDEN=1 $(CARGO) test --test it golden
	INSTA_UPDATE=always $(CARGO) test --test it

## Benchmarks (release profile).
bench:
	$(CARGO) bench

doc:
	RUSTDOCFLAGS="-D warnings" $(CARGO) doc --no-deps

clean:
	$(CARGO) clean
