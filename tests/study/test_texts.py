"""Built-in participant texts per language, a design's language and [texts] (issue 18, item 6)."""
from __future__ import annotations

from pathlib import Path

import pytest

from fixtures.synthetic import write_synthetic_study
from studyapp.study.design import DesignError, load_design, validate_design
from studyapp.study.design import texts as T


def test_every_language_has_exactly_the_english_keys_and_fields():
    for code, table in T.LANGUAGES.items():
        assert set(table) == set(T.EN), (code, set(table) ^ set(T.EN))
        assert [k for k in T.EN if T.fields(T.EN[k]) != T.fields(table[k])] == [], code


def _study(tmp_path: Path, top: str):
    path = write_synthetic_study(tmp_path / "s", n_stimuli=1, seconds=1.0, practice=False)
    # top-level keys before the first table, the [texts] table at the end
    head, _, table = top.partition("[texts]")
    path.write_text(head + "\n" + path.read_text() + ("\n[texts]" + table if table else "") + "\n")
    return path


def test_language_picks_the_table_and_texts_override_it(tmp_path):
    d = load_design(_study(tmp_path, 'language = "zh"\n[texts]\n"page.continue" = "下一步"\n'))
    assert d.text("page.continue") == "下一步"
    assert d.text("progress.clip", k=2, n=5) == "第 2 / 5 个片段"
    # a design without criteria gets the default three in its language
    assert [c.label for c in d.criteria] == ["真实感", "同步性", "多样性"]


@pytest.mark.parametrize("code", ["zh-Hans", "zh_CN", "ZH-cn"])
def test_common_tags_of_a_shipped_language_pick_its_table(tmp_path, code):
    d = load_design(_study(tmp_path, f'language = "{code}"\n'))
    assert d.language == "zh" and d.text("progress.clip", k=2, n=5) == "第 2 / 5 个片段"


@pytest.mark.parametrize("top,key,words", [
    ('[texts]\n"page.contineu" = "Go"', "texts.page.contineu", "unknown text key"),
    ('[texts]\n"progress.clip" = "Clip {k}"', "texts.progress.clip", "same fields"),
    ('[texts]\n"page.continue" = 3', "texts.page.continue", "string"),
    ('language = "fr"', "language", "no built-in texts"),
])
def test_each_texts_problem_is_one_message(tmp_path, top, key, words):
    probs = validate_design(_study(tmp_path, top), check_files=False)
    assert [p.key for p in probs] == [key], probs
    assert words in probs[0].message
    if "contineu" in top:
        assert "page.continue" in probs[0].fix  # did you mean


def test_several_unknown_keys_are_one_message_each(tmp_path):
    probs = validate_design(_study(tmp_path, '[texts]\n"a.b" = "x"\n"c.d" = "y"'), check_files=False)
    assert sorted(p.key for p in probs) == ["texts.a.b", "texts.c.d"]


def test_an_override_naming_a_condition_unblinds_and_is_refused(tmp_path):
    with pytest.raises(DesignError) as err:
        load_design(_study(tmp_path, '[texts]\n"page.continue" = "On to synced"'))
    assert any(p.key == "texts.page.continue" and "unblinds" in p.message for p in err.value.problems)


def test_validate_says_when_no_installed_font_has_the_characters(tmp_path, monkeypatch):
    from studyapp.study.design import fonts

    path = _study(tmp_path, 'language = "zh"')
    monkeypatch.setattr(fonts, "fallback_font", lambda chars: None)
    probs = validate_design(path)
    assert [p.key for p in probs] == ["language"]
    assert "no installed font" in probs[0].message and "fonts-noto-cjk" in probs[0].fix


def test_an_english_design_needs_no_extra_font(tmp_path):
    from studyapp.study.design.fonts import design_fallback_font

    assert design_fallback_font(load_design(_study(tmp_path, ""))) == (None, set())


def test_the_characters_taken_on_trust_are_in_the_ui_font():
    """validate skips loading the UI font for texts made only of these: each must really be in Roboto."""
    from studyapp.study.design.fonts import SURELY_IN_UI_FONT, charmap, ui_font_path

    have = charmap(str(ui_font_path()))
    assert have and sorted(c for c in SURELY_IN_UI_FONT if ord(c) not in have) == []


def test_the_built_in_consent_fits_every_paradigm():
    """The default consent page is the first page of every study, whatever its blocks ask: it may not promise
    three figures to rank (a pairwise or mismatch study shows two, a rating study asks for sliders)."""
    from studyapp.study.design.texts import LANGUAGES

    assert "three" not in LANGUAGES["en"]["welcome.consent"] and "rank" not in LANGUAGES["en"]["welcome.consent"]
    assert "三个" not in LANGUAGES["zh"]["welcome.consent"] and "排序" not in LANGUAGES["zh"]["welcome.consent"]


def test_preference_instructions_name_the_figures_as_the_answers_do():
    """The answers read "Clearly A" .. "Clearly B"; the instructions must use the same names, not only
    left/right (a participant met "1 = clearly the left figure" above boxes saying A and B)."""
    for lang, table in T.LANGUAGES.items():
        how = T.fill(table["instructions.how_pref"], n=5, first="Ⓐ", last="Ⓑ")
        assert "Ⓐ" in how and "Ⓑ" in how, lang
