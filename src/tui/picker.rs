//! The scene picker `mpmlab` opens when started without a scene: the
//! scenes of a folder with their descriptions, the default highlighted.
//! State, pure drawing, and a small event loop (arrows/jk move, Enter
//! opens, q or Esc quits).

use ratatui::layout::{Constraint, Layout};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::Line;
use ratatui::widgets::{Block, Borders, List, ListItem, ListState, Paragraph, Wrap};
use ratatui::Frame;
use std::path::PathBuf;

/// One scene on offer.
#[derive(Clone, Debug)]
pub struct Entry {
    pub path: PathBuf,
    pub name: String,
    pub description: String,
}

/// The picker's state.
pub struct Picker {
    pub entries: Vec<Entry>,
    pub selected: usize,
    /// Index of the default scene (marked).
    pub default: usize,
}

impl Picker {
    pub fn up(&mut self) {
        self.selected = self.selected.saturating_sub(1);
    }
    pub fn down(&mut self) {
        self.selected = (self.selected + 1).min(self.entries.len().saturating_sub(1));
    }
}

/// Draw the picker: the list on the left, the selected scene's description
/// on the right.
pub fn draw(frame: &mut Frame, p: &Picker) {
    let [title, body, status] =
        Layout::vertical([Constraint::Length(1), Constraint::Min(3), Constraint::Length(1)]).areas(frame.area());
    frame.render_widget(
        Paragraph::new(" mpmlab — choose a scene").style(Style::new().add_modifier(Modifier::BOLD)),
        title,
    );
    let [list, about] = Layout::horizontal([Constraint::Percentage(40), Constraint::Percentage(60)]).areas(body);
    let items: Vec<ListItem> = p
        .entries
        .iter()
        .enumerate()
        .map(|(k, e)| {
            let mark = if k == p.default { " (default)" } else { "" };
            ListItem::new(format!("{}{mark}", e.name))
        })
        .collect();
    let mut state = ListState::default().with_selected(Some(p.selected));
    frame.render_stateful_widget(
        List::new(items)
            .block(Block::default().borders(Borders::ALL).title(" scenes "))
            .highlight_style(Style::new().bg(Color::Blue).add_modifier(Modifier::BOLD))
            .highlight_symbol("> "),
        list,
        &mut state,
    );
    let e = &p.entries[p.selected];
    frame.render_widget(
        Paragraph::new(vec![
            Line::raw(e.path.display().to_string()),
            Line::raw(""),
            Line::raw(e.description.clone()),
        ])
        .wrap(Wrap { trim: true })
        .block(Block::default().borders(Borders::ALL).title(format!(" {} ", e.name))),
        about,
    );
    frame.render_widget(
        Paragraph::new(" up/down choose · enter open · q quit").style(Style::new().fg(Color::Gray)),
        status,
    );
}

/// Let the user choose; `None` when they quit.
pub fn pick(mut p: Picker) -> std::io::Result<Option<Entry>> {
    use ratatui::crossterm::event::{self, Event, KeyCode, KeyEventKind};
    if p.entries.is_empty() {
        return Ok(None);
    }
    let mut terminal = ratatui::init();
    let result = (|| -> std::io::Result<Option<Entry>> {
        loop {
            terminal.draw(|f| draw(f, &p))?;
            if let Event::Key(k) = event::read()? {
                if k.kind != KeyEventKind::Press {
                    continue;
                }
                match k.code {
                    KeyCode::Up | KeyCode::Char('k') => p.up(),
                    KeyCode::Down | KeyCode::Char('j') => p.down(),
                    KeyCode::Enter => return Ok(Some(p.entries[p.selected].clone())),
                    KeyCode::Char('q') | KeyCode::Esc => return Ok(None),
                    _ => {}
                }
            }
        }
    })();
    ratatui::restore();
    result
}
