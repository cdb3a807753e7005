"""Every built-in text a participant reads, one table per language, and how a design overrides them.

A design picks a table with ``language`` (``"en"``, the default, or ``"zh"``: Simplified Chinese) and
overrides any entry in its ``[texts]`` table (``[texts] "page.continue" = "Weiter"``); the keys are the
ones below, and an unknown key is a design problem. Texts hold ``{name}`` fields that the screens fill
(``{minutes}``, ``{k}``, ``{n}``, ...); an override must keep the fields of the text it replaces.

To add a language: copy :data:`EN` into a new dict here (every key, same ``{fields}``), translate the
values, and add it to :data:`LANGUAGES` under its code; ``tests/study/test_texts.py`` checks that every
table has exactly EN's keys and fields. Right-to-left scripts (Arabic, Hebrew) are not supported: the UI
lays text out left to right only.

>>> fill(LANGUAGES["en"]["progress.clip"], k=3, n=8)
'Clip 3 of 8'
>>> fill(LANGUAGES["zh"]["progress.clip"], k=3, n=8)
'第 3 / 8 个片段'
"""
from __future__ import annotations

import re
from typing import Any

EN: dict[str, str] = {
    # full pages: shared
    "page.continue": "Continue",
    "page.press_enter": "or press Enter",
    "page.more_below": "More text below: scroll down (mouse wheel or Page Down).",
    # welcome and consent
    "welcome.title": "Welcome",
    "welcome.consent": ("In this study you will watch short clips of animated figures talking and answer a few "
                        "questions about them. It takes about {minutes} minutes. Your answers are saved as you go, under "
                        "a participant code, without your name. You can stop at any time by closing the window; "
                        "nothing else is recorded."),
    "welcome.agree_note": ("By pressing \"I agree, start\" you agree to take part and to your anonymous answers being "
                           "used for research. If you do not want to take part, press \"I do not agree\"."),
    "welcome.agree": "I agree, start",
    "welcome.decline": "I do not agree",
    "welcome.decline_ask": "End the study now, without taking part? Only that choice is recorded.",
    "welcome.decline_confirm": "Yes, end without taking part",
    "welcome.decline_back": "No, go back",
    "welcome.keys_tip": ("Tip: everything works with the keyboard too (Enter continues on every page), and F11 "
                         "switches full screen on and off."),
    "welcome.back_title": "Welcome back",
    "welcome.back_clip": "You are continuing at clip {k} of {n}. Your earlier answers are saved.",
    "welcome.back_practice": "You are continuing at practice clip {k} of {n}. Your earlier answers are saved.",
    "welcome.back_dropped": ("Last time you had started this clip but not finished your answer. That unfinished "
                             "answer was not saved; you will see the clip again from the start."),
    # instructions
    "instructions.title": "Instructions",
    "instructions.questions": "The questions",
    "instructions.how_title": "How to rank",
    "instructions.how": (
        "After a clip has played to the end, a panel opens below the figures. For each question, put the three "
        "figures in order from best (1st) to worst (3rd): drag a figure's letter into a box, or click the letters "
        "in order from best to worst. Keyboard: the number keys choose a figure, not a rank: {keys} puts that "
        "figure in the next free box, so pressing them in your order from best to worst ranks the question. "
        "Up/Down change question, Backspace clears a question, Enter goes to the next clip. Space pauses and "
        "resumes the clip."),
    "instructions.ties": (
        "If two or three figures seem equally good, you may rank them as equal: click the > sign between their "
        "boxes so that it shows = (keyboard: press = before placing the next figure, e.g. 1 = 2 3). Equal figures "
        "share the better place: two equal best figures are both 1st, and the other one is 3rd."),
    # computer check
    "env.title": "Checking your computer",
    "env.measuring": "Measuring graphics speed and audio output; this takes a moment...",
    "env.pass": "OK",
    "env.warn": "Check",
    "env.fail": "Problem",
    "env.graphics": "Graphics",
    "env.graphics.pass": "The figures can be shown.",
    "env.graphics.fail": "This computer cannot show the figures.",
    "env.screen": "Screen",
    "env.screen.pass": "The screen is fine.",
    "env.screen.warn": "The screen may show movement less smoothly.",
    "env.sound": "Sound",
    "env.sound.pass": "Sound works.",
    "env.sound.warn": "Sound works, a little late; wired headphones are better.",
    "env.sound.fail": "No sound output was found: the clips would be silent.",
    "env.animation": "Animation",
    "env.animation.pass": "The figures move smoothly.",
    "env.animation.warn": "The figures may move a little less smoothly.",
    "env.animation.fail": "The figures would move too jerkily.",
    "env.verdict.pass": "Everything is ready.",
    "env.verdict.warn": "Ready. Something marked \"Check\" may be a little worse than ideal.",
    "env.verdict.fail": "There is a problem with this computer (see above).",
    "env.sound_title": "Sound check",
    "env.sound_text": ("Put on your headphones and press the button: you should hear a short beep. Adjust the volume "
                       "so it is comfortable. The clips use the same output."),
    "env.sound_button": "Play test sound (T)",
    "env.sound_played": "Played. If you heard nothing, check the volume or tell the experimenter.",
    "env.tell": "Please tell the experimenter before you continue.",
    "env.continue_anyway": "Continue anyway",
    # trials
    "progress.clip": "Clip {k} of {n}",
    "progress.practice": "Practice clip {k} of {n}",
    "trial.loading": "Loading the next clip...",
    "trial.practice_note": "Practice: its answers are not analysed.",
    "trial.play": "Play",
    "trial.pause": "Pause",
    "trial.resume": "Resume",
    "trial.replay": "Replay",
    "trial.stop": "Stop",
    "trial.ready": "Press Play (or Space) to watch the clip with sound.",
    "trial.paused": "Paused. Press Resume or Space to continue.",
    "trial.watch": "Watch to the end; the questions appear afterwards. Space pauses.",
    "trial.replaying": "Replaying. Space pauses.",
    "trial.rank_now": "Now rank the three figures below.",
    "trial.rank_replay": "Rank the three figures below. You may replay the clip as often as you like.",
    "rank.first": "1st (best)",
    "rank.second": "2nd",
    "rank.third": "3rd (worst)",
    "rank.tied": "{ordinal} (tied)",
    "rank.ordinal1": "1st",
    "rank.ordinal2": "2nd",
    "rank.ordinal3": "3rd",
    "rank.drop_here": "drop here",
    "rank.key": "key {n}",
    "rank.done": "Done. Click a box to change it.",
    "rank.start_hint": "Drag or click the letters into the boxes, best first; or press {keys}.",
    "rank.tie_hint": "Click > to tie two.",
    "rank.tie_on": "Equal. Click to make them different again.",
    "rank.tie_off": "Click to make these two equal.",
    "rank.next_ok": "Enter = next. You cannot come back to this clip.",
    "rank.wait": "Available when the clip has finished.",
    "rank.still": "Still to rank: {criteria}",
    "rank.next": "Next clip",
    "rank.next_practice": "Next practice clip",
    "rank.start_study": "Start the study",
    "rank.finish": "Finish",
    # the other answer panels (pairwise and mismatch: a preference; rating: sliders) and a block's own page
    "trial.answer_now": "Now answer the questions below.",
    "trial.answer_replay": "Answer the questions below. You may replay the clip as often as you like.",
    "pref.clearly": "Clearly {figure}",
    "pref.slightly": "Slightly {figure}",
    "pref.better": "{figure} is better",
    "pref.equal": "No preference",
    "pref.reasons": "What made the difference? (optional, tick any)",
    "pref.start_hint": "Click an answer for each question, or press its key 1-{n}; Up/Down change question.",
    "pref.still": "Still to answer: {criteria}",
    "rating.unset": "not rated yet",
    "rating.start_hint": "Set every slider: click or drag it, or press Left/Right or 1-{n}; Up/Down change slider.",
    "rating.still": "Still to rate: {sliders}",
    "block.title": "The next part",
    "block.continue": "Start this part",
    "instructions.how_answer_title": "How to answer",
    "instructions.how_pref": (
        "After a clip has played to the end, a panel opens below the two figures. For each question, say which "
        "figure you prefer, and how clearly: click one of the answers, or press its number key, shown above it "
        "(1 = clearly {first}, the figure on the left ... {n} = clearly {last}, the one on the right; the middle "
        "one means no preference). "
        "Left/Right move the answer one step, Up/Down change question, Backspace clears it, Enter goes to the "
        "next clip. Space pauses and resumes the clip."),
    "instructions.how_reasons": (
        "When you prefer one figure, you may also tick what made the difference (optional): click the boxes, or "
        "press Down to reach them and their number keys."),
    "instructions.how_rating": (
        "After a clip has played to the end, a slider appears below each figure for each question. Rate every "
        "figure from 0 (worst) to 100 (best): click or drag on its slider. Every slider must be set before you "
        "can go on. Keyboard: Up/Down choose a slider, Left/Right move it by 1, Page Up/Page Down by 10, the "
        "number keys 1-{n} jump along the scale from low to high (onto the labels, when it has some); Enter "
        "goes to the next clip. Space pauses and resumes the clip."),
    # the criteria used when a design has none
    "criteria.realism.label": "Realism",
    "criteria.realism.question": "Which motion looks most realistic?",
    "criteria.realism.explanation": ("Natural human movement: no odd body orientation, no jitter, no frozen or "
                                     "robotic poses."),
    "criteria.synchronization.label": "Synchronization",
    "criteria.synchronization.question": "Which motion is best synchronized with the speech?",
    "criteria.synchronization.explanation": ("The gestures follow the rhythm and intonation of the speech: emphasis "
                                             "in the voice comes with movement, pauses with calm."),
    "criteria.diversity.label": "Diversity",
    "criteria.diversity.question": "Which motion is most diverse?",
    "criteria.diversity.explanation": ("Rich and varied gestures: not motionless, not the same movement repeated "
                                       "over and over."),
    # questionnaire
    "questionnaire.title": "A few last questions",
    "questionnaire.intro": "Please tell us about your experience. Answer every question (written comments are optional).",
    "questionnaire.missing": "Please answer every question (written comments are optional).",
    "questionnaire.submit": "Submit answers",
    "questionnaire.all_that_apply": "Choose all that apply.",
    "questionnaire.number": "A number from {min} to {max}.",
    "questionnaire.whole_number": "A whole number from {min} to {max}.",
    "questionnaire.out_of_range": "Please enter a number from {min} to {max}.",
    "questionnaire.keys_likert": "Keyboard: press 1-{n} to answer, Up/Down arrows for another question",
    "questionnaire.keys_choice": "Keyboard: press 1-{n} to choose, Up/Down arrows for another question",
    "questionnaire.keys_choices": "Keyboard: press 1-{n} to tick or untick an option, Up/Down arrows for another question",
    "questionnaire.keys_text": "Keyboard: type your answer, then press Enter",
    # the end
    "final.done": "Study complete",
    "final.ended_early": "The study has ended",
    "final.declined": "Thank you",
    "final.done_text": "Thank you! You have completed the study. Your answers have been saved.",
    "final.ended_early_text": ("Thank you for your time. The study has ended early because check questions were not "
                               "answered as expected. This can happen to anyone, and your participation is "
                               "appreciated. Your answers so far have been saved."),
    "final.declined_text": ("You have chosen not to take part. Thank you for considering it. Nothing about you has "
                            "been recorded apart from that choice."),
    "final.file_title": "Your results file",
    "final.file_text": ("Please send this file to the experimenter (for example as an e-mail attachment). It "
                        "contains only your answers and your participant code."),
    "final.saved_title": "Your answers are saved",
    "final.saved_db": "Results database: {path}",
    "final.saved_text": "Nothing more is needed from you. Please let the experimenter know that you have finished.",
    "final.close_window": "You can now close this window.",
    "final.close": "Close",
    # the browser study (studyapp serve)
    "online.already_done": "This study has already been completed (or ended) with this link; it cannot be taken again.",
    "online.expired": ("This session was left unfinished for too long and has been closed. Thank you for your "
                       "time."),
    "online.bad_link": "This study link is not valid. Please open the study again from where you found it.",
    "online.code": "Your completion code: {code}",
    "online.return": "Return to the study platform",
    "online.sound_heard": "I heard the sound",
    "online.not_saved": "Your answer could not be saved: {problem}",
    "online.busy": "Too many requests at once; please wait a moment and try again.",
}

ZH: dict[str, str] = {
    "page.continue": "继续",
    "page.press_enter": "或按回车键",
    "page.more_below": "下面还有内容：请向下滚动（鼠标滚轮或 Page Down 键）。",
    "welcome.title": "欢迎",
    "welcome.consent": ("在本研究中，您将观看一些会说话的动画人物的短片，并回答关于它们的几个问题。整个过程大约需要 "
                        "{minutes} 分钟。您的回答会随时保存，只记录参与者编号，不记录您的姓名。您可以随时关闭窗口退出；"
                        "除此之外不会记录任何信息。"),
    "welcome.agree_note": "点击“我同意，开始”即表示您同意参与，并同意您的匿名回答用于研究。如果您不想参与，请点击“我不同意”。",
    "welcome.agree": "我同意，开始",
    "welcome.decline": "我不同意",
    "welcome.decline_ask": "现在结束、不参与本研究吗？只会记录这一选择。",
    "welcome.decline_confirm": "是的，不参与并结束",
    "welcome.decline_back": "不，返回",
    "welcome.keys_tip": "提示：所有操作也都可以用键盘完成（每一页按回车键继续），按 F11 可切换全屏。",
    "welcome.back_title": "欢迎回来",
    "welcome.back_clip": "您将从第 {k} / {n} 个片段继续。您之前的回答已保存。",
    "welcome.back_practice": "您将从第 {k} / {n} 个练习片段继续。您之前的回答已保存。",
    "welcome.back_dropped": "上次您已开始这个片段，但没有完成回答。未完成的回答没有保存；这个片段将从头重新播放。",
    "instructions.title": "说明",
    "instructions.questions": "问题",
    "instructions.how_title": "如何排序",
    "instructions.how": (
        "片段播放完毕后，人物下方会出现一个面板。请针对每个问题，把三个人物从最好（第 1）到最差（第 3）排序：把人物的字母"
        "拖到方框中，或按从好到差的顺序依次点击字母。键盘：数字键选择的是人物，而不是名次：{keys} 会把该人物放入下一个空方框，"
        "所以按您从好到差的顺序按数字键即可完成该问题的排序。上/下方向键切换问题，退格键清除当前问题，回车键进入下一个片段。"
        "空格键暂停和继续播放。"),
    "instructions.ties": (
        "如果两个或三个人物看起来一样好，可以把它们排为并列：点击它们方框之间的 > 符号，使其变为 =（键盘：在放入下一个人物之前"
        "按 =，例如 1 = 2 3）。并列的人物共享较好的名次：两个并列最好的人物都是第 1，另一个是第 3。"),
    "env.title": "正在检查您的电脑",
    "env.measuring": "正在测量图形速度和音频输出，请稍候……",
    "env.pass": "正常",
    "env.warn": "请注意",
    "env.fail": "有问题",
    "env.graphics": "图形",
    "env.graphics.pass": "可以显示人物。",
    "env.graphics.fail": "这台电脑无法显示人物。",
    "env.screen": "屏幕",
    "env.screen.pass": "屏幕正常。",
    "env.screen.warn": "屏幕显示的动作可能不够流畅。",
    "env.sound": "声音",
    "env.sound.pass": "声音正常。",
    "env.sound.warn": "声音正常，但略有延迟；建议使用有线耳机。",
    "env.sound.fail": "没有找到音频输出：片段将没有声音。",
    "env.animation": "动画",
    "env.animation.pass": "人物动作流畅。",
    "env.animation.warn": "人物动作可能略不流畅。",
    "env.animation.fail": "人物动作会过于卡顿。",
    "env.verdict.pass": "一切就绪。",
    "env.verdict.warn": "可以开始。标为“请注意”的项目可能不够理想。",
    "env.verdict.fail": "这台电脑有问题（见上文）。",
    "env.sound_title": "声音测试",
    "env.sound_text": "请戴上耳机并点击按钮：您应该会听到一声短促的提示音。请把音量调到舒适的程度。片段使用同一个输出设备。",
    "env.sound_button": "播放测试音 (T)",
    "env.sound_played": "已播放。如果没有听到声音，请检查音量或告诉实验人员。",
    "env.tell": "继续之前请告诉实验人员。",
    "env.continue_anyway": "仍然继续",
    "progress.clip": "第 {k} / {n} 个片段",
    "progress.practice": "第 {k} / {n} 个练习片段",
    "trial.loading": "正在加载下一个片段……",
    "trial.practice_note": "练习：其回答不计入分析。",
    "trial.play": "播放",
    "trial.pause": "暂停",
    "trial.resume": "继续",
    "trial.replay": "重播",
    "trial.stop": "停止",
    "trial.ready": "点击“播放”（或按空格键）观看有声片段。",
    "trial.paused": "已暂停。点击“继续”或按空格键继续。",
    "trial.watch": "请看到结尾；之后会出现问题。空格键暂停。",
    "trial.replaying": "正在重播。空格键暂停。",
    "trial.rank_now": "现在请对下面的三个人物排序。",
    "trial.rank_replay": "请对下面的三个人物排序。您可以随意重播这个片段。",
    "rank.first": "第 1（最好）",
    "rank.second": "第 2",
    "rank.third": "第 3（最差）",
    "rank.tied": "{ordinal}（并列）",
    "rank.ordinal1": "第 1",
    "rank.ordinal2": "第 2",
    "rank.ordinal3": "第 3",
    "rank.drop_here": "拖到这里",
    "rank.key": "按键 {n}",
    "rank.done": "完成。点击方框可以修改。",
    "rank.start_hint": "把字母拖入或点入方框，最好的在前；或按 {keys}。",
    "rank.tie_hint": "点击 > 可设为并列。",
    "rank.tie_on": "并列。点击可取消并列。",
    "rank.tie_off": "点击使这两个并列。",
    "rank.next_ok": "回车 = 下一个。您无法回到这个片段。",
    "rank.wait": "片段播放完毕后可用。",
    "rank.still": "尚未排序：{criteria}",
    "rank.next": "下一个片段",
    "rank.next_practice": "下一个练习片段",
    "rank.start_study": "开始正式实验",
    "rank.finish": "完成",
    "trial.answer_now": "现在请回答下面的问题。",
    "trial.answer_replay": "请回答下面的问题。您可以随意重播这个片段。",
    "pref.clearly": "明显{figure}更好",
    "pref.slightly": "稍微{figure}更好",
    "pref.better": "{figure}更好",
    "pref.equal": "没有偏好",
    "pref.reasons": "是什么造成了差别？（可选，可多选）",
    "pref.start_hint": "为每个问题点击一个答案，或按对应的按键 1-{n}；上/下方向键切换问题。",
    "pref.still": "尚未回答：{criteria}",
    "rating.unset": "尚未评分",
    "rating.start_hint": "请设置每个滑块：点击或拖动，或按左/右方向键或 1-{n}；上/下方向键切换滑块。",
    "rating.still": "尚未评分：{sliders}",
    "block.title": "下一部分",
    "block.continue": "开始这一部分",
    "instructions.how_answer_title": "如何作答",
    "instructions.how_pref": (
        "片段播放完毕后，两个人物下方会出现一个面板。请针对每个问题，说明您更喜欢哪个人物以及程度：点击其中一个答案，"
        "或按答案上方显示的数字键（1 = 明显{first}（左边的人物）更好 …… {n} = 明显{last}（右边的人物）更好；中间的表示没有偏好）。"
        "左/右方向键把答案移动一格，上/下方向键切换问题，退格键清除答案，回车键进入下一个片段。空格键暂停和继续播放。"),
    "instructions.how_reasons": "当您更喜欢其中一个人物时，还可以勾选造成差别的原因（可选）：点击方框，或按下方向键移到原因处再按数字键。",
    "instructions.how_rating": (
        "片段播放完毕后，每个人物下方会针对每个问题出现一个滑块。请给每个人物从 0（最差）到 100（最好）评分："
        "点击或拖动它的滑块。必须设置每个滑块后才能继续。键盘：上/下方向键选择滑块，左/右方向键移动 1，"
        "Page Up/Page Down 移动 10，数字键 1-{n} 从低到高跳到刻度上的位置（有标签时即标签处）；回车键进入下一个片段。空格键暂停和继续播放。"),
    "criteria.realism.label": "真实感",
    "criteria.realism.question": "哪个动作看起来最真实？",
    "criteria.realism.explanation": "自然的人体动作：没有奇怪的身体朝向，没有抖动，没有僵住或机械的姿势。",
    "criteria.synchronization.label": "同步性",
    "criteria.synchronization.question": "哪个动作与语音最同步？",
    "criteria.synchronization.explanation": "手势跟随语音的节奏和语调：语音重读时有动作，停顿时保持平静。",
    "criteria.diversity.label": "多样性",
    "criteria.diversity.question": "哪个动作最多样？",
    "criteria.diversity.explanation": "丰富多变的手势：不是一动不动，也不是反复做同一个动作。",
    "questionnaire.title": "最后几个问题",
    "questionnaire.intro": "请告诉我们您的体验。请回答每个问题（文字意见可以不填）。",
    "questionnaire.missing": "请回答每个问题（文字意见可以不填）。",
    "questionnaire.submit": "提交回答",
    "questionnaire.all_that_apply": "可多选。",
    "questionnaire.number": "{min} 到 {max} 之间的数字。",
    "questionnaire.whole_number": "{min} 到 {max} 之间的整数。",
    "questionnaire.out_of_range": "请输入 {min} 到 {max} 之间的数字。",
    "questionnaire.keys_likert": "键盘：按 1-{n} 作答，上/下方向键切换问题",
    "questionnaire.keys_choice": "键盘：按 1-{n} 选择，上/下方向键切换问题",
    "questionnaire.keys_choices": "键盘：按 1-{n} 勾选或取消选项，上/下方向键切换问题",
    "questionnaire.keys_text": "键盘：输入您的回答，然后按回车键",
    "final.done": "实验完成",
    "final.ended_early": "实验已结束",
    "final.declined": "谢谢",
    "final.done_text": "谢谢！您已完成本研究。您的回答已保存。",
    "final.ended_early_text": "感谢您抽出时间。由于检查题的回答与预期不符，实验已提前结束。这种情况任何人都可能遇到，我们感谢您的参与。您目前的回答已保存。",
    "final.declined_text": "您选择了不参与。感谢您的考虑。除了这一选择之外，没有记录任何关于您的信息。",
    "final.file_title": "您的结果文件",
    "final.file_text": "请把这个文件发送给实验人员（例如作为电子邮件附件）。文件中只有您的回答和参与者编号。",
    "final.saved_title": "您的回答已保存",
    "final.saved_db": "结果数据库：{path}",
    "final.saved_text": "您无需再做任何事。请告诉实验人员您已完成。",
    "final.close_window": "现在可以关闭此窗口。",
    "final.close": "关闭",
    # the browser study (studyapp serve)
    "online.already_done": "此链接已用于完成（或结束）本研究，不能再次参加。",
    "online.expired": "此会话未完成且闲置时间过长，已被关闭。感谢您的时间。",
    "online.bad_link": "此研究链接无效。请从您获得研究的地方重新打开。",
    "online.code": "您的完成代码：{code}",
    "online.return": "返回研究平台",
    "online.sound_heard": "我听到了声音",
    "online.not_saved": "您的回答未能保存：{problem}",
    "online.busy": "请求过多；请稍候再试。",
}

#: Shipped tables by language code (see the module docstring to add one).
LANGUAGES: dict[str, dict[str, str]] = {"en": EN, "zh": ZH}

#: Other codes people write for a shipped table (BCP 47 tags, compared case-insensitively, ``_`` read as ``-``).
ALIASES = {"zh-hans": "zh", "zh-cn": "zh", "zh-sg": "zh", "zh-hans-cn": "zh", "en-us": "en", "en-gb": "en"}


def language_code(code: str) -> str:
    """The shipped table's code for ``code``: ``"zh-Hans"`` -> ``"zh"``; an unknown code is returned as given.

    >>> language_code("zh-Hans"), language_code("zh_CN"), language_code("en"), language_code("fr")
    ('zh', 'zh', 'en', 'fr')
    """
    key = str(code).strip().lower().replace("_", "-")
    return key if key in LANGUAGES else ALIASES.get(key, code)

_FIELD = re.compile(r"\{(\w+)\}")


def fields(template: str) -> set[str]:
    """The ``{name}`` fields of a text."""
    return set(_FIELD.findall(template))


def fill(template: str, **values: Any) -> str:
    """``template`` with its ``{name}`` fields replaced (other braces, e.g. in a design's text, are kept)."""
    return _FIELD.sub(lambda m: str(values[m.group(1)]) if m.group(1) in values else m.group(0), template)


def table(language: str, overrides: dict[str, str] | None = None) -> dict[str, str]:
    """The texts a design shows: the language's table (English for an unknown code) with its overrides."""
    return {**LANGUAGES.get(language, EN), **(overrides or {})}


def text(design: Any, key: str, **values: Any) -> str:
    """The text ``key`` of ``design`` (its language and ``[texts]``; English for objects without them)."""
    texts = getattr(design, "texts", None) or EN
    return fill(texts.get(key, EN[key]), **values)
