//! pest parse tree -> AST. The grammar is `hyb.pest` beside this file (its rule names are the
//! AST's); this file is the only one that sees pest's `Pair`s. Operator precedence is applied
//! here with pest's Pratt parser.

use std::sync::OnceLock;

use pest::error::{ErrorVariant, InputLocation};
use pest::iterators::{Pair, Pairs};
use pest::pratt_parser::{Assoc, Op, PrattParser};
use pest::Parser;

use super::ast::*;
use super::{ParseError, Span};

#[derive(pest_derive::Parser)]
#[grammar = "syntax/hyb.pest"]
struct HybParser;

/// Parses a whole `.hyb` source text.
pub fn parse(source: &str) -> Result<File, ParseError> {
    // Track the literal tokens tried at the furthest position, for "expected `,`" messages.
    pest::set_error_detail(true);
    check_limits(source)?;
    let mut pairs = HybParser::parse(Rule::file, source).map_err(|e| convert_error(source, e))?;
    let file = pairs.next().expect("the file rule always yields one pair");
    build_file(file)
}

/// Longest line accepted. Statements end at the line end, so this bounds every expression and
/// with it the recursion depth of every later stage.
const MAX_LINE_LEN: usize = 4096;
/// Deepest parenthesis nesting accepted (the parser recurses on each level).
const MAX_NESTING: usize = 64;

/// Rejects inputs whose shape would exhaust the stack of a recursive stage.
fn check_limits(source: &str) -> Result<(), ParseError> {
    let mut line_start = 0;
    let mut depth = 0usize;
    let mut braces = 0usize;
    for (i, c) in source.char_indices() {
        match c {
            // Line ends as the grammar's NEWLINE counts them: LF, CRLF, or a lone CR.
            '\n' | '\r' => {
                line_start = i + 1;
                continue;
            }
            '(' => depth += 1,
            ')' => depth = depth.saturating_sub(1),
            // Blocks span lines: `for` loops nest, and each level is a recursion of the parser.
            '{' => braces += 1,
            '}' => braces = braces.saturating_sub(1),
            _ => {}
        }
        if braces > MAX_NESTING {
            return Err(ParseError {
                span: Span::new(i, i + 1),
                message: format!("blocks nested more than {MAX_NESTING} deep"),
                expected: "fewer nested `for` loops".to_string(),
            });
        }
        if depth > MAX_NESTING {
            return Err(ParseError {
                span: Span::new(i, i + 1),
                message: format!("parentheses nested more than {MAX_NESTING} deep"),
                expected: "a flatter expression (use `let`)".to_string(),
            });
        }
        if i - line_start >= MAX_LINE_LEN {
            return Err(ParseError {
                span: Span::new(i, i + c.len_utf8()),
                message: format!("line longer than {MAX_LINE_LEN} characters"),
                expected: "a shorter line (split the expression with `let`)".to_string(),
            });
        }
    }
    Ok(())
}

fn span_of(pair: &Pair<Rule>) -> Span {
    let s = pair.as_span();
    Span::new(s.start(), s.end())
}

fn ident(pair: Pair<Rule>) -> Ident {
    debug_assert_eq!(pair.as_rule(), Rule::ident);
    Ident { name: pair.as_str().to_string(), span: span_of(&pair) }
}

fn number(pair: Pair<Rule>) -> Result<Number, ParseError> {
    let span = span_of(&pair);
    use crate::number::{parse_number, NumberError};
    let text = pair.as_str();
    let value = parse_number(text).map_err(|e| match e {
        NumberError::TooLarge { .. } | NumberError::NotFinite { .. } => ParseError {
            span,
            message: format!("number `{text}` is too large"),
            expected: "a finite number".to_string(),
        },
        // A literal that rounds to 0 would silently be 0 (`param a = 1e-400`).
        NumberError::TooSmall { .. } => ParseError {
            span,
            message: format!("number `{text}` is too small for a double: it would round to 0"),
            expected: "a number of magnitude at least 4.9e-324, or 0".to_string(),
        },
        NumberError::NotANumber { .. } => {
            ParseError { span, message: format!("`{text}` is not a number"), expected: String::new() }
        }
    })?;
    Ok(Number { value, span })
}

fn build_file(pair: Pair<Rule>) -> Result<File, ParseError> {
    // Line ends are significant in the grammar but carry nothing for the AST.
    let mut inner = pair.into_inner().filter(|p| p.as_rule() != Rule::nl);
    let model_decl = inner.next().expect("grammar: model_decl first");
    let model = ident(model_decl.into_inner().nth(1).expect("grammar: model name"));
    let mut items = Vec::new();
    for p in inner {
        if p.as_rule() == Rule::EOI {
            break;
        }
        items.push(build_item(p)?);
    }
    Ok(File { model, items })
}

fn build_item(pair: Pair<Rule>) -> Result<Item, ParseError> {
    let span = span_of(&pair);
    Ok(match pair.as_rule() {
        Rule::param_decl => {
            let mut it = pair.into_inner().skip(1);
            let name = ident(it.next().expect("grammar: param name"));
            let mut next = it.next().expect("grammar: param default");
            let mut size = None;
            if next.as_rule() == Rule::size {
                let count = next.into_inner().next().expect("grammar: size count");
                if count.as_rule() == Rule::count {
                    // More digits than a u64 holds is simply too long; sema caps the length anyway.
                    let len = count.as_str().parse::<u64>().unwrap_or(u64::MAX);
                    let (text, span) = (count.as_str().to_string(), span_of(&count));
                    size = Some(Size { expr: None, text, len, span });
                } else {
                    let (text, span) = (count.as_str().to_string(), span_of(&count));
                    size = Some(Size { expr: Some(build_expr(count)?), text, len: 0, span });
                }
                next = it.next().expect("grammar: param default");
            }
            let default = number(next)?;
            let range = match it.next() {
                Some(r) => {
                    let rspan = span_of(&r);
                    let mut ri = r.into_inner().skip(1);
                    let lo = number(ri.next().expect("grammar: range lo"))?;
                    let hi = number(ri.next().expect("grammar: range hi"))?;
                    Some(Range { lo, hi, span: rspan })
                }
                None => None,
            };
            Item::Param(ParamDecl { name, size, default, range, span })
        }
        Rule::state_decl => {
            let mut it = pair.into_inner().skip(1).peekable();
            let name = ident(it.next().expect("grammar: state name"));
            let index = subscripts(&mut it)?;
            let init = build_expr(it.next().expect("grammar: state init"))?;
            Item::State(StateDecl { name, index, init, span })
        }
        Rule::der_eq => Item::Der(build_der(pair)?),
        Rule::let_decl => Item::Let(build_let(pair)?),
        Rule::output_decl => {
            let mut it = pair.into_inner().skip(1).peekable();
            let name = ident(it.next().expect("grammar: output name"));
            let index = subscripts(&mut it)?;
            let value = build_expr(it.next().expect("grammar: output value"))?;
            Item::Output(OutputDecl { name, index, value, span })
        }
        Rule::const_decl => {
            let mut it = pair.into_inner().skip(1);
            let name = ident(it.next().expect("grammar: const name"));
            let value = build_expr(it.next().expect("grammar: const value"))?;
            Item::Const(ConstDecl { name, value, span })
        }
        Rule::for_loop => {
            let mut it = pair
                .into_inner()
                .filter(|p| !matches!(p.as_rule(), Rule::kw_for | Rule::kw_in | Rule::dots | Rule::nl));
            let var = ident(it.next().expect("grammar: loop variable"));
            let lo = build_expr(it.next().expect("grammar: loop start"))?;
            let hi = build_expr(it.next().expect("grammar: loop end"))?;
            let items = it.map(build_item).collect::<Result<Vec<_>, _>>()?;
            Item::For(Box::new(ForLoop { var, lo, hi, items, span }))
        }
        Rule::simulate_decl => {
            let mut settings = Vec::new();
            for s in pair.into_inner().skip(1) {
                let sspan = span_of(&s);
                let mut si = s.into_inner();
                let name = ident(si.next().expect("grammar: setting name"));
                let value = number(si.next().expect("grammar: setting value"))?;
                settings.push(Setting { name, value, span: sspan });
            }
            Item::Simulate(SimulateDecl { settings, span })
        }
        Rule::event_decl => Item::Event(Box::new(build_event(pair)?)),
        Rule::mode_decl => Item::Mode(Box::new(build_mode(pair)?)),
        other => unreachable!("grammar: unexpected item {other:?}"),
    })
}

/// The `[e]` subscripts that follow a declared name, if any.
fn subscripts<'i>(
    it: &mut std::iter::Peekable<impl Iterator<Item = Pair<'i, Rule>>>,
) -> Result<Vec<Expr>, ParseError> {
    let mut out = Vec::new();
    while let Some(p) = it.next_if(|p| p.as_rule() == Rule::subscript) {
        out.push(build_expr(p.into_inner().next().expect("grammar: subscript expression"))?);
    }
    Ok(out)
}

fn build_der(pair: Pair<Rule>) -> Result<DerEq, ParseError> {
    let span = span_of(&pair);
    let mut it = pair.into_inner().skip(1).peekable();
    let state = ident(it.next().expect("grammar: der state"));
    let index = subscripts(&mut it)?;
    let rhs = build_expr(it.next().expect("grammar: der rhs"))?;
    Ok(DerEq { state, index, rhs, span })
}

fn build_let(pair: Pair<Rule>) -> Result<LetDecl, ParseError> {
    let span = span_of(&pair);
    let mut it = pair.into_inner().skip(1).peekable();
    let name = ident(it.next().expect("grammar: let name"));
    let index = subscripts(&mut it)?;
    let value = build_expr(it.next().expect("grammar: let value"))?;
    Ok(LetDecl { name, index, value, span })
}

fn build_event(pair: Pair<Rule>) -> Result<EventDecl, ParseError> {
    let span = span_of(&pair);
    let mut it = pair.into_inner().peekable();
    it.next(); // kw_event
    let name = ident(it.next().expect("grammar: event name"));
    let index = subscripts(&mut it)?;
    it.next(); // kw_when
    let lhs = build_expr(it.next().expect("grammar: guard lhs"))?;
    let op = match it.next().expect("grammar: guard op").as_str() {
        "<=" => GuardOp::Le,
        "<" => GuardOp::Lt,
        ">=" => GuardOp::Ge,
        ">" => GuardOp::Gt,
        _ => GuardOp::Crosses,
    };
    let rhs = build_expr(it.next().expect("grammar: guard rhs"))?;
    let mut event =
        EventDecl { name, index, lhs, op, rhs, condition: None, target: None, body: Vec::new(), span };
    for p in it {
        match p.as_rule() {
            Rule::enable => {
                let c = p.into_inner().nth(1).expect("grammar: enable cond");
                event.condition = Some(build_cond(c)?);
            }
            Rule::target => {
                event.target = Some(ident(p.into_inner().next().expect("grammar: target")));
            }
            Rule::event_block => {
                for s in p.into_inner().filter(|s| s.as_rule() != Rule::nl) {
                    let sspan = span_of(&s);
                    event.body.push(match s.as_rule() {
                        Rule::reset => {
                            let mut si = s.into_inner().peekable();
                            let state = ident(si.next().expect("grammar: reset state"));
                            let index = subscripts(&mut si)?;
                            let value = build_expr(si.next().expect("grammar: reset value"))?;
                            EventStmt::Reset { state, index, value, span: sspan }
                        }
                        Rule::let_decl => EventStmt::Let(build_let(s)?),
                        Rule::stop => EventStmt::Stop { span: sspan },
                        other => unreachable!("grammar: unexpected event statement {other:?}"),
                    });
                }
            }
            other => unreachable!("grammar: unexpected event part {other:?}"),
        }
    }
    Ok(event)
}

fn build_mode(pair: Pair<Rule>) -> Result<ModeDecl, ParseError> {
    let span = span_of(&pair);
    let mut is_initial = false;
    let mut name = None;
    let mut items = Vec::new();
    for p in pair.into_inner() {
        match p.as_rule() {
            Rule::initial => is_initial = true,
            Rule::kw_mode | Rule::nl => {}
            Rule::ident => name = Some(ident(p)),
            Rule::der_eq => items.push(ModeItem::Der(build_der(p)?)),
            Rule::let_decl => items.push(ModeItem::Let(build_let(p)?)),
            Rule::event_decl => items.push(ModeItem::Event(Box::new(build_event(p)?))),
            other => unreachable!("grammar: unexpected mode part {other:?}"),
        }
    }
    let name = name.expect("grammar: mode name");
    Ok(ModeDecl { name, is_initial, items, span })
}

fn expr_parser() -> &'static PrattParser<Rule> {
    static PARSER: OnceLock<PrattParser<Rule>> = OnceLock::new();
    PARSER.get_or_init(|| {
        // Lowest precedence first. Unary minus sits below `^`, so `-x^2` is `-(x^2)`.
        PrattParser::new()
            .op(Op::infix(Rule::add, Assoc::Left) | Op::infix(Rule::sub, Assoc::Left))
            .op(Op::infix(Rule::mul, Assoc::Left) | Op::infix(Rule::div, Assoc::Left))
            .op(Op::prefix(Rule::neg))
            .op(Op::infix(Rule::pow, Assoc::Right))
    })
}

fn cond_parser() -> &'static PrattParser<Rule> {
    static PARSER: OnceLock<PrattParser<Rule>> = OnceLock::new();
    PARSER.get_or_init(|| {
        PrattParser::new()
            .op(Op::infix(Rule::or_op, Assoc::Left))
            .op(Op::infix(Rule::and_op, Assoc::Left))
            .op(Op::prefix(Rule::not_op))
    })
}

fn join(a: Span, b: Span) -> Span {
    Span::new(a.start.min(b.start), a.end.max(b.end))
}

fn build_expr(pair: Pair<Rule>) -> Result<Expr, ParseError> {
    debug_assert_eq!(pair.as_rule(), Rule::expr);
    climb_expr(pair.into_inner())
}

fn climb_expr(pairs: Pairs<Rule>) -> Result<Expr, ParseError> {
    expr_parser()
        .map_primary(build_primary)
        .map_prefix(|op, rhs| {
            let rhs = rhs?;
            let span = join(span_of(&op), rhs.span);
            Ok(Expr { kind: ExprKind::Neg(Box::new(rhs)), span })
        })
        .map_infix(|lhs, op, rhs| {
            let (lhs, rhs) = (lhs?, rhs?);
            let bin = match op.as_rule() {
                Rule::add => BinOp::Add,
                Rule::sub => BinOp::Sub,
                Rule::mul => BinOp::Mul,
                Rule::div => BinOp::Div,
                _ => BinOp::Pow,
            };
            let span = join(lhs.span, rhs.span);
            Ok(Expr { kind: ExprKind::Binary(bin, Box::new(lhs), Box::new(rhs)), span })
        })
        .parse(pairs)
}

fn build_primary(pair: Pair<Rule>) -> Result<Expr, ParseError> {
    let span = span_of(&pair);
    let kind = match pair.as_rule() {
        Rule::number => ExprKind::Num(number(pair)?.value),
        Rule::ident => ExprKind::Name(pair.as_str().to_string()),
        Rule::expr => return build_expr(pair),
        Rule::call => {
            let mut it = pair.into_inner();
            let name = ident(it.next().expect("grammar: call name"));
            let args = it.map(build_expr).collect::<Result<Vec<_>, _>>()?;
            ExprKind::Call(name, args)
        }
        Rule::index => {
            let mut it = pair.into_inner().peekable();
            let name = ident(it.next().expect("grammar: index name"));
            ExprKind::Index(name, subscripts(&mut it)?)
        }
        Rule::reduction => {
            let mut it =
                pair.into_inner().filter(|p| !matches!(p.as_rule(), Rule::kw_sum | Rule::kw_in | Rule::dots));
            let var = ident(it.next().expect("grammar: sum variable"));
            let lo = build_expr(it.next().expect("grammar: sum start"))?;
            let hi = build_expr(it.next().expect("grammar: sum end"))?;
            let body = build_expr(it.next().expect("grammar: sum term"))?;
            ExprKind::Sum(Box::new(Reduction { var, lo, hi, body }))
        }
        Rule::if_expr => {
            let mut it = pair
                .into_inner()
                .filter(|p| !matches!(p.as_rule(), Rule::kw_if | Rule::kw_then | Rule::kw_else));
            let c = build_cond(it.next().expect("grammar: if cond"))?;
            let a = build_expr(it.next().expect("grammar: then"))?;
            let b = build_expr(it.next().expect("grammar: else"))?;
            ExprKind::If(Box::new(c), Box::new(a), Box::new(b))
        }
        other => unreachable!("grammar: unexpected primary {other:?}"),
    };
    Ok(Expr { kind, span })
}

fn build_cond(pair: Pair<Rule>) -> Result<Cond, ParseError> {
    debug_assert_eq!(pair.as_rule(), Rule::cond);
    cond_parser()
        .map_primary(|p| match p.as_rule() {
            Rule::compare => {
                let span = span_of(&p);
                let mut it = p.into_inner();
                let a = build_expr(it.next().expect("grammar: compare lhs"))?;
                let op = match it.next().expect("grammar: compare op").as_str() {
                    "<=" => CmpOp::Le,
                    "<" => CmpOp::Lt,
                    ">=" => CmpOp::Ge,
                    _ => CmpOp::Gt,
                };
                let b = build_expr(it.next().expect("grammar: compare rhs"))?;
                Ok(Cond { kind: CondKind::Cmp(op, a, b), span })
            }
            Rule::cond => build_cond(p),
            other => unreachable!("grammar: unexpected condition {other:?}"),
        })
        .map_prefix(|op, rhs| {
            let rhs = rhs?;
            let span = join(span_of(&op), rhs.span);
            Ok(Cond { kind: CondKind::Not(Box::new(rhs)), span })
        })
        .map_infix(|lhs, op, rhs| {
            let (lhs, rhs) = (lhs?, rhs?);
            let span = join(lhs.span, rhs.span);
            let kind = match op.as_rule() {
                Rule::and_op => CondKind::And(Box::new(lhs), Box::new(rhs)),
                _ => CondKind::Or(Box::new(lhs), Box::new(rhs)),
            };
            Ok(Cond { kind, span })
        })
        .parse(pair.into_inner())
}

/// The grammar's `keyword` rule, word for word.
const KEYWORDS: [&str; 22] = [
    "model", "param", "state", "der", "let", "event", "when", "if", "then", "else", "mode", "initial",
    "output", "simulate", "in", "and", "or", "not", "crosses", "stop", "const", "for",
];

const LINE_END: &str = "the end of the line";
const FILE_END: &str = "the end of the file";

/// Human names for what the parser expected, in the words of the language reference.
fn describe(rule: Rule) -> Option<&'static str> {
    Some(match rule {
        Rule::model_decl | Rule::kw_model => "`model NAME`",
        Rule::ident => "a name",
        Rule::number | Rule::signed_number => "a number",
        Rule::expr | Rule::neg => "an expression",
        Rule::cond | Rule::compare => "a condition",
        Rule::cmp_op => "a comparison (`<`, `<=`, `>`, `>=`)",
        Rule::guard_op => "a guard operator (`<=`, `<`, `>=`, `>`, `crosses`)",
        Rule::add | Rule::sub | Rule::mul | Rule::div | Rule::pow => "an operator",
        Rule::and_op | Rule::or_op => "`and` / `or`",
        Rule::not_op => "`not`",
        Rule::param_decl | Rule::kw_param => "a statement",
        Rule::state_decl | Rule::kw_state => "a statement",
        Rule::der_eq | Rule::kw_der => "a statement",
        Rule::let_decl | Rule::kw_let => "a statement",
        Rule::event_decl | Rule::kw_event => "a statement",
        Rule::mode_decl | Rule::kw_mode | Rule::initial | Rule::kw_initial => "a statement",
        Rule::output_decl | Rule::kw_output => "a statement",
        Rule::simulate_decl | Rule::kw_simulate => "a statement",
        Rule::reset => "a reset `x := ...`",
        Rule::stop | Rule::kw_stop => "`stop`",
        Rule::range | Rule::kw_in => "`in [LO, HI]`",
        Rule::enable | Rule::kw_if => "`if`",
        Rule::kw_then => "`then`",
        Rule::kw_else => "`else`",
        Rule::kw_when => "`when`",
        Rule::target => "`-> MODE`",
        Rule::event_block => "`{`",
        Rule::setting => "a setting `name = value`",
        Rule::call => "a function call",
        Rule::index => "an element `u[k]`",
        Rule::const_decl | Rule::kw_const => "a statement",
        Rule::for_loop | Rule::kw_for => "a statement",
        Rule::dots => "`..`",
        Rule::reduction => "an expression",
        Rule::size | Rule::count => "a length `[N]`",
        Rule::if_expr => "an expression",
        Rule::EOI => FILE_END,
        Rule::nl => LINE_END,
        _ => return None,
    })
}

fn convert_error(source: &str, err: pest::error::Error<Rule>) -> ParseError {
    let mut pos = match err.location {
        InputLocation::Pos(p) => p,
        InputLocation::Span((s, _)) => s,
    };
    let mut expected: Vec<String> = Vec::new();
    let mut push = |d: String| {
        if !expected.contains(&d) {
            expected.push(d);
        }
    };
    if let Some((at, found)) = furthest_attempt(source, &err, pos) {
        pos = at;
        found.into_iter().for_each(&mut push);
    } else if let ErrorVariant::ParsingError { positives, .. } = &err.variant {
        for &rule in positives {
            if let Some(d) = describe(rule) {
                push(d.to_string());
            }
        }
    }
    // Where a line could end, "the end of the file" is only the special case of the last line.
    if expected.iter().any(|e| e == LINE_END) {
        expected.retain(|e| e != FILE_END);
    }
    let expected = match expected.len() {
        0 => "something else".to_string(),
        1 => expected[0].to_string(),
        n => format!("{} or {}", expected[..n - 1].join(", "), expected[n - 1]),
    };
    let found = found_at(source, pos);
    let end = (pos + found.1).min(source.len());
    let word = found.0.trim_matches('`');
    // A keyword where a name was wanted: say why the word is refused (`const` and `for` were
    // names before arrays reserved them).
    let message = if expected.contains("a name") && KEYWORDS.contains(&word) {
        format!("`{word}` is a reserved keyword")
    } else {
        format!("unexpected {}", found.0)
    };
    ParseError { span: Span::new(pos, end.max(pos)), message, expected }
}

/// The furthest position the parser reached and what it wanted there, when that says more than
/// pest's rule-level error: it knows the punctuation that was missing (`,`, `]`, `:=`).
fn furthest_attempt(
    source: &str,
    err: &pest::error::Error<Rule>,
    pos: usize,
) -> Option<(usize, Vec<String>)> {
    let attempts = err.parse_attempts()?;
    let at = attempts.max_position;
    // Past a keyword's last letter the attempt stands on blank space; the rule-level error is
    // clearer there.
    if at < pos || source[at..].starts_with([' ', '\t']) {
        return None;
    }
    let mut found: Vec<String> = Vec::new();
    for stack in attempts.call_stacks() {
        // An optional `[i]` after a declared name is never what was missed: name the
        // declaration it was part of (`state y 1`: "a statement or `=`").
        let rule = match stack.deepest.get_rule() {
            Some(Rule::subscript) => stack.parent.as_ref(),
            r => r,
        };
        if let Some(d) = rule.and_then(|r| describe(*r)) {
            found.push(d.to_string());
        }
    }
    let mut has_operator = false;
    let mut has_bracket = false;
    for token in attempts.expected_tokens() {
        let token = token.to_string();
        match token.as_str() {
            // A comment, or the continuation of a name or number: never what the user missed.
            "#" | "_" | "." | "" => {}
            "+" | "-" | "*" | "/" | "^" => has_operator = true,
            "(" if found.iter().any(|f| f == "an expression") => {}
            // After a name, `[` would make it an element `u[k]`: true but never what was missed
            // where an operator could follow (dropped below, once the operators are known).
            "[" => has_bracket = true,
            t if t.chars().all(|c| c.is_ascii_punctuation()) => found.push(format!("`{t}`")),
            _ => {}
        }
    }
    if has_operator {
        found.push("an operator".to_string());
    } else if has_bracket && found.is_empty() {
        found.push("`[`".to_string());
    }
    found.dedup();
    if found.is_empty() {
        return None;
    }
    Some((at, found))
}

/// What stands at `pos`, in words, and how many bytes of it to underline.
fn found_at(source: &str, pos: usize) -> (String, usize) {
    let rest = source.get(pos..).unwrap_or("");
    let Some(c) = rest.chars().next() else {
        return ("end of file".to_string(), 0);
    };
    if c == '\n' || c == '\r' {
        return ("end of line".to_string(), 0);
    }
    if super::chars::is_invisible(c) {
        let kind = if c.is_control() {
            "control character"
        } else if super::chars::is_combining(c) {
            "combining character"
        } else {
            "invisible character"
        };
        return (format!("{kind} {}", super::chars::escaped(c)), c.len_utf8());
    }
    let word: String =
        rest.chars().take_while(|ch| ch.is_alphanumeric() || *ch == '_' || *ch == '.').collect();
    if word.is_empty() {
        (format!("`{c}`"), c.len_utf8())
    } else {
        (format!("`{word}`"), word.len())
    }
}
