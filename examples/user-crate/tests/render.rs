//! The scene's image against its golden (tests/golden/scenes/ball.ray.png),
//! and the two backends against each other.

#[test]
fn ball_matches_its_golden() {
    rendiff::assert_golden!("scenes/ball.toml");
}

#[test]
fn ball_looks_the_same_to_both_backends() {
    rendiff::assert_agree!("scenes/ball.toml");
}
