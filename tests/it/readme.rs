//! The README cannot drift: every example it shows as `$ rendiff …` in a
//! text block is run here, and its output must be what the block says
//! (times aside, which vary from run to run).

use std::process::Command;

use crate::util::root;

/// Times in milliseconds vary; everything else must match.
fn normalise(text: &str) -> String {
    let mut out = String::new();
    for line in text.lines() {
        let words: Vec<String> = line
            .split(' ')
            .collect::<Vec<_>>()
            .windows(2)
            .map(|w| {
                if w[1].starts_with("ms") && w[0].parse::<f64>().is_ok() {
                    "T".to_string()
                } else {
                    w[0].to_string()
                }
            })
            .collect();
        let last = line.split(' ').next_back().unwrap_or_default();
        out.push_str(&words.join(" "));
        if !words.is_empty() {
            out.push(' ');
        }
        out.push_str(last);
        out.push('\n');
    }
    out
}

/// The README's examples: (command line, expected output).
fn examples() -> Vec<(String, String)> {
    let text = std::fs::read_to_string(root().join("README.md")).unwrap();
    let mut out = Vec::new();
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        if line.trim() != "```text" {
            continue;
        }
        let block: Vec<&str> = lines.by_ref().take_while(|l| l.trim() != "```").collect();
        if let Some(cmd) = block.first().and_then(|l| l.strip_prefix("$ rendiff ")) {
            out.push((cmd.to_string(), block[1..].join("\n") + "\n"));
        }
    }
    out
}

#[test]
fn every_readme_example_prints_what_the_readme_shows() {
    let examples = examples();
    assert!(
        !examples.is_empty(),
        "the README shows no `$ rendiff` example"
    );
    for (cmd, want) in examples {
        let o = Command::new(env!("CARGO_BIN_EXE_rendiff"))
            .args(cmd.split_whitespace())
            .current_dir(root())
            .output()
            .unwrap();
        let got = String::from_utf8_lossy(&o.stdout).into_owned();
        assert_eq!(
            normalise(&got),
            normalise(&want),
            "`rendiff {cmd}` prints (left) what the README does not show (right); update the README:\n{got}"
        );
    }
}
